# Evaluation: the dataset reference row's grasps, per-grasp metrics per task and method, Table 1 with the
# QR grid, and the qualitative figures (predicted hands in their scenes, contact maps next to the truth).


rule reference_grasps:
    input:
        shards=test_shards,
        code=code("data/predictions", "data/maps", "data/store", "grasps/expand"),
    output:
        directory("results/predictions/{task}/dataset.zarr"),
    params:
        samples=setting("prediction", "samples"),
        seed=setting("evaluation", "dataset_seed"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/predictions/{task}/dataset.log",
    script:
        "../scripts/reference_grasps.py"


rule evaluate:
    input:
        predictions="results/predictions/{task}/{method}.zarr",
        scenes=test_scene_stores,
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
        code=code("metrics/evaluate", "metrics/quality", "data/predictions", "data/scenes", "data/store", "grasps/expand",
                  "geometry/raycast", "config"),
    output:
        "results/metrics/{task}/{method}.parquet",
    params:
        sd=setting("metrics", "sd"),
        voxel_pitch=setting("metrics", "voxel_pitch"),
        cache_dir=setting("cache_dir"),
    threads: config["evaluation"]["threads"]
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/metrics/{task}/{method}.log",
    benchmark:
        "results/benchmarks/metrics/{task}/{method}.tsv"
    script:
        "../scripts/evaluate.py"


rule table1:
    input:
        metrics=metric_outputs,
        code=code("metrics/tables", "metrics/evaluate"),
    output:
        csv=report("results/tables/table1.csv", caption="../report/table1.rst", category="Tables"),
        md="results/tables/table1.md",
        grid=report("results/tables/qr_grid.csv", caption="../report/qr_grid.rst", category="Tables"),
    params:
        tasks=setting("scenes", "tasks"),
        methods=setting("evaluation", "methods"),
        qr=setting("evaluation", "qr"),
        qr_grid=setting("evaluation", "qr_grid"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/tables/table1.log",
    script:
        "../scripts/table1.py"


rule predictions_figure:
    input:
        predictions="results/predictions/{task}/ours.zarr",
        scenes=test_scene_stores,
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
        code=code("viz/predictions", "viz/render", "viz/scenes", "sim", "data/predictions", "data/scenes", "data/maps",
                  "data/store"),
    output:
        report("results/figures/predictions_{task}.png", caption="../report/predictions.rst", category="Evaluation"),
    params:
        configs=setting("figures", "prediction_configs"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/figures/predictions_{task}.log",
    script:
        "../scripts/predictions_figure.py"


rule contact_maps_figure:
    input:
        predictions=expand("results/predictions/{task}/ours.zarr", task=config["scenes"]["tasks"]),
        shards=all_test_shards,
        code=code("viz/predictions", "viz/render", "viz/scenes", "sim", "data/predictions", "data/maps", "data/store"),
    output:
        report("results/figures/contact_maps.png", caption="../report/contact_maps.rst", category="Evaluation"),
    params:
        configs=setting("figures", "prediction_configs"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/figures/contact_maps.log",
    script:
        "../scripts/contact_maps_figure.py"
