# The scenes stage: Placing, Stacking and Shelving configurations per task and target object, and a
# picture per task.


rule scenes:
    input:
        objects=object_dirs(),
        supports="results/objects/supports",
    output:
        directory("results/scenes/{task}/{object}.zarr"),
    params:
        code=code("scenes.py"),
        objects_dir=objects_dir_of_supports,
        settings=scene_settings,
        seed=setting("seed"),
    resources:
        **rule_resources("scenes"),
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/scenes/{task}/{object}.log",
    benchmark:
        "results/benchmarks/scenes/{task}/{object}.tsv"
    script:
        "../scripts/scenes.py"


rule scenes_figure:
    input:
        scenes=scene_stores,
        supports="results/objects/supports",
    output:
        report("results/figures/scenes_{task}.png", caption="../report/scenes.rst", category="Scenes"),
    params:
        code=code("scenes_figure.py"),
        objects_dir=objects_dir_of_supports,
        max_configs=setting("figures", "scene_configs"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/figures/scenes_{task}.log",
    script:
        "../scripts/scenes_figure.py"
