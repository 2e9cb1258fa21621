# The official TOHGS dataset (config official.import_dir; docs/official_dataset.md): the import's objects,
# catalog, supports, scene stores, task grasps and test configurations, copied into results/ where the
# later stages read generated data. These rules replace rules/objects.smk, scenes.smk and grasps.smk. A copy
# is no cluster job's worth: they run where Snakemake runs (localrule).


rule official_object:
    input:
        imported("objects/{object}"),
    output:
        directory("results/objects/{object}"),
    log:
        "logs/official/objects/{object}.log",
    priority: PRIORITY["data"]
    localrule: True
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("official_copy.py"),
    script:
        "../scripts/official_copy.py"


rule catalog:
    input:
        imported("objects/catalog.csv"),
    output:
        "results/objects/catalog.csv",
    log:
        "logs/official/catalog.log",
    priority: PRIORITY["data"]
    localrule: True
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("official_copy.py"),
    script:
        "../scripts/official_copy.py"


rule supports:
    input:
        imported("objects/supports"),
    output:
        directory("results/objects/supports"),
    log:
        "logs/official/supports.log",
    priority: PRIORITY["data"]
    localrule: True
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("official_copy.py"),
    script:
        "../scripts/official_copy.py"


rule official_scenes:
    input:
        imported("scenes/{task}/{object}.zarr"),
    output:
        directory("results/scenes/{task}/{object}.zarr"),
    log:
        "logs/official/scenes/{task}/{object}.log",
    priority: PRIORITY["data"]
    localrule: True
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("official_copy.py"),
    script:
        "../scripts/official_copy.py"


rule official_task_grasps:
    input:
        imported("grasps/task/{task}/{object}.zarr"),
    output:
        directory("results/grasps/task/{task}/{object}.zarr"),
    log:
        "logs/official/task_grasps/{task}/{object}.log",
    priority: PRIORITY["data"]
    localrule: True
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("official_copy.py"),
    script:
        "../scripts/official_copy.py"


rule official_test_scenes:
    input:
        imported("test_scenes/{task}/{object}.zarr"),
    output:
        directory("results/test_scenes/{task}/{object}.zarr"),
    log:
        "logs/official/test_scenes/{task}/{object}.log",
    priority: PRIORITY["data"]
    localrule: True
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("official_copy.py"),
    script:
        "../scripts/official_copy.py"
