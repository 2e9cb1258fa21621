# The scenes stage: Placing, Stacking and Shelving configurations per task and target object (generated
# data; rules/official.smk has the imported ones).


rule scenes:
    input:
        objects=object_dirs(),
        supports="results/objects/supports",
    output:
        directory("results/scenes/{task}/{object}.zarr"),
    log:
        "logs/scenes/{task}/{object}.log",
    benchmark:
        "results/benchmarks/scenes/{task}/{object}.tsv"
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    resources:
        **rule_resources("scenes"),
    params:
        code=code("scenes.py"),
        objects_dir=objects_dir_of_supports,
        settings=scene_settings,
        seed=setting("seed"),
    script:
        "../scripts/scenes.py"
