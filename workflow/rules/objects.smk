# The objects stage: select, validate, normalise and decompose every object; the catalog with the
# split by object; the table and shelves (generated data; rules/official.smk has the imported ones).


rule prepare_object:
    input:
        source=object_source,
    output:
        directory("results/objects/{object}"),
    log:
        "logs/objects/{object}.log",
    benchmark:
        "results/benchmarks/objects/{object}.tsv"
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    resources:
        **rule_resources("prepare_object"),
    params:
        code=code("prepare_object.py"),
        spec=object_spec,
        size=object_size,
        density=setting("objects", "density"),
        decomposition=setting("objects", "decomposition"),
        limits=setting("objects", "limits"),
        cache_dir=setting("cache_dir"),
    script:
        "../scripts/prepare_object.py"


checkpoint catalog:
    input:
        objects=object_dirs(),
    output:
        "results/objects/catalog.csv",
    log:
        "logs/objects/catalog.log",
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("catalog.py"),
        split=setting("objects", "split"),
        dir_split=setting("objects", "sources", "dir", "split"),
        seed=setting("seed"),
        task_sets=TASK_SETS,
        skipped=[list(s) for s in SKIPPED_FILES],  # user-folder files that are no objects, with the reason
    script:
        "../scripts/catalog.py"


rule supports:
    output:
        directory("results/objects/supports"),
    log:
        "logs/objects/supports.log",
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("supports.py"),
        table=setting("objects", "supports", "table"),
        shelves=setting("objects", "supports", "shelves"),
    script:
        "../scripts/supports.py"
