# Components and methods: training per task and component, then test predictions per task and method.


rule train:
    input:
        shards=train_shards,
        hand="results/hand/hand.npz",
    output:
        model="results/models/{task}/{component}.pt",
        curve=report(
            "results/models/{task}/{component}.png",
            caption="../report/training.rst",
            category="Training",
        ),
    log:
        "logs/models/{task}/{component}.log",
    benchmark:
        "results/benchmarks/models/{task}/{component}.tsv"
    priority: PRIORITY["train"]
    conda:
        "../envs/tohgs.yaml"
    threads: config["training"]["threads"]
    resources:
        **rule_resources("train"),
    params:
        code=lambda w: code("train.py", f"models/{COMPONENTS[w.component]['kind']}"),
        kind=lambda w: COMPONENTS[w.component]["kind"],
        network=lambda w: _canonical(job_network(COMPONENTS[w.component], _SCHEMA)),
        settings=component_settings,
    script:
        "../scripts/train.py"


rule predict:
    input:
        shards=test_shards,
        models=method_models,
        hand="results/hand/hand.npz",
        base=method_base,
    output:
        directory("results/predictions/{task}/{method}.zarr"),
    log:
        "logs/predictions/{task}/{method}.log",
    benchmark:
        "results/benchmarks/predictions/{task}/{method}.tsv"
    priority: PRIORITY["predict"]
    conda:
        "../envs/tohgs.yaml"
    threads: method_threads
    resources:
        **rule_resources("predict"),
    params:
        code=method_code,
        method=method_block,
        settings=method_settings,
    script:
        "../scripts/predict.py"


rule model_checks:
    input:
        shards=train_shards,
        models=lambda w: [
            f"results/models/{w.task}/{c}.pt" for c in checked_components()
        ],
        hand="results/hand/hand.npz",
    output:
        "results/models/{task}/checks.json",
    log:
        "logs/models/{task}/checks.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("model_checks.py", *(f"models/{kind}" for kind in CHECKS_OF_KIND)),
        checks=lambda w: {
            c: CHECKS_OF_KIND[COMPONENTS[c]["kind"]]
            for c in sorted(checked_components())
        },
        seed=setting("training", "seed"),
    script:
        "../scripts/model_checks.py"
