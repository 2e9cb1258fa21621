# The prior-grasp stage: force-closure synthesis and metrics per object (expensive; SD only for the grasps
# that pass the filter's energy and joint-limit checks), then the filter (cheap, so a PV, SD or contact
# threshold change reruns only it), a per-object summary and a picture; then the task
# expansion per task and object (generated data; rules/official.smk has the imported task grasps).


rule prior_synthesis:
    input:
        object="results/objects/{object}",
        hand="results/hand/hand.npz",
    output:
        directory("results/grasps/prior/raw/{object}.zarr"),
    log:
        "logs/grasps/prior_synthesis/{object}.log",
    benchmark:
        "results/benchmarks/grasps/prior_synthesis/{object}.tsv"
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    threads: config["prior_grasps"]["threads"]
    resources:
        **rule_resources("prior_synthesis"),
    params:
        code=code("prior_synthesis.py"),
        synthesis=setting("prior_grasps", "synthesis"),
        sdf=setting("prior_grasps", "sdf"),
        sd=setting("metrics", "sd"),
        voxel_pitch=setting("metrics", "voxel_pitch"),
        plane_direction=plane_direction,
        screen=prior_screen,
        hand_model=setting("hand", "model"),
        seed=setting("seed"),
        cache_dir=setting("cache_dir"),
    script:
        "../scripts/prior_synthesis.py"


rule prior_filter:
    input:
        raw="results/grasps/prior/raw/{object}.zarr",
    output:
        directory("results/grasps/prior/{object}.zarr"),
    log:
        "logs/grasps/prior_filter/{object}.log",
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    resources:
        **rule_resources("prior_filter"),
    params:
        code=code("prior_filter.py"),
        thresholds=setting("prior_grasps", "filter"),
    script:
        "../scripts/prior_filter.py"


rule prior_summary:
    input:
        stores=prior_stores,
    output:
        "results/grasps/prior/summary.csv",
    log:
        "logs/grasps/prior_summary.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("prior_summary.py"),
    script:
        "../scripts/prior_summary.py"


rule prior_figure:
    input:
        stores=prior_stores,
        catalog="results/objects/catalog.csv",
        hand="results/hand/hand.npz",
    output:
        report(
            "results/figures/prior_grasps.png",
            caption="../report/prior_grasps.rst",
            category="Prior grasps",
        ),
    log:
        "logs/figures/prior_grasps.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("prior_figure.py"),
        objects_dir=objects_dir_of_catalog,
        n_objects=setting("figures", "prior_objects"),
    script:
        "../scripts/prior_figure.py"


rule task_grasps:
    input:
        scenes="results/scenes/{task}/{object}.zarr",
        prior="results/grasps/prior/{object}.zarr",
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
    output:
        directory("results/grasps/task/{task}/{object}.zarr"),
    log:
        "logs/grasps/task/{task}/{object}.log",
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    resources:
        **rule_resources("task_grasps"),
    params:
        code=code("task_grasps.py"),
        objects_dir=objects_dir_of_supports,
        settings=setting("task_grasps"),
    script:
        "../scripts/task_grasps.py"
