# Pictures of the stages' inputs, generated or imported: the objects, and the scenes per task.


rule objects_figure:
    input:
        catalog="results/objects/catalog.csv",
        objects=object_dirs(),
    output:
        report(
            "results/figures/objects.png",
            caption="../report/objects.rst",
            category="Objects",
        ),
    log:
        "logs/figures/objects.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("objects_figure.py"),
        max_objects=setting("figures", "max_objects"),
        seed=setting("seed"),
    script:
        "../scripts/objects_figure.py"


rule scenes_figure:
    input:
        scenes=scene_stores,
        supports="results/objects/supports",
    output:
        report(
            "results/figures/scenes_{task}.png",
            caption="../report/scenes.rst",
            category="Scenes",
        ),
    log:
        "logs/figures/scenes_{task}.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("scenes_figure.py"),
        objects_dir=objects_dir_of_supports,
        max_configs=setting("figures", "scene_configs"),
    script:
        "../scripts/scenes_figure.py"
