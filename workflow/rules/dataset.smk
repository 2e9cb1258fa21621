# The task-oriented dataset: distance and contact maps in Zarr shards per task, split and shard
# (independent jobs) from the scene stores and task grasps, generated or imported; a summary and a picture.


rule maps:
    input:
        scenes=split_scene_stores,
        grasps=split_task_grasps,
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
    output:
        directory("results/maps/{task}/{split}/shard-{shard}.zarr"),
    log:
        "logs/maps/{task}/{split}/shard-{shard}.log",
    benchmark:
        "results/benchmarks/maps/{task}/{split}/shard-{shard}.tsv"
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    resources:
        **rule_resources("maps"),
    params:
        code=code("maps.py"),
        objects_dir=objects_dir_of_supports,
        settings=setting("maps", "points"),
        n_shards=lambda w: config["maps"]["shards"][w.split],
        test_configs=setting("maps", "test_configs"),
        seed=setting("seed"),
    script:
        "../scripts/maps.py"


rule dataset_summary:
    input:
        task_grasps=all_task_grasps,
        scenes=all_scene_stores,
        shards=all_map_shards,
        objects=object_dirs(),
        supports="results/objects/supports",
    output:
        "results/maps/summary.csv",
    log:
        "logs/maps/summary.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("dataset_summary.py"),
        objects_dir=objects_dir_of_supports,
        seed=setting("seed"),
    script:
        "../scripts/dataset_summary.py"


rule maps_figure:
    input:
        shards=all_map_shards,
        hand="results/hand/hand.npz",
    output:
        report(
            "results/figures/maps.png",
            caption="../report/maps.rst",
            category="Dataset",
        ),
    log:
        "logs/figures/maps.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("maps_figure.py"),
    script:
        "../scripts/maps_figure.py"
