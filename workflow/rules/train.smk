# The diffusers: training per task and model, then test predictions per task and method.


rule train:
    input:
        shards=train_shards,
        hand="results/hand/hand.npz",
        code=code("models/train", "models/diffusion", "models/pointnet2", "models/contact_diffuser",
                  "models/grasp_diffuser", "data/maps", "data/store", "grasps/expand", "config"),
    output:
        model="results/models/{task}/{model}.pt",
        curve=report("results/models/{task}/{model}.png", caption="../report/training.rst", category="Training"),
    params:
        model=lambda w: setting("models", w.model),
        settings=lambda w: _canonical({**config["training"]["common"], **config["training"][w.model]}),
    threads: config["training"]["common"]["threads"]
    resources:
        gpu=1,  # a hint for cluster executors; local runs ignore resources they are not given
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/models/{task}/{model}.log",
    benchmark:
        "results/benchmarks/models/{task}/{model}.tsv"
    script:
        "../scripts/train.py"


rule predict:
    wildcard_constraints:
        method="ours|ours-gt-contact",
    input:
        shards=test_shards,
        grasp_model="results/models/{task}/grasp_diffuser.pt",
        contact_model=contact_model_of,
        code=code("models", "data/maps", "data/store", "data/predictions", "grasps/expand"),
    output:
        directory("results/predictions/{task}/{method}.zarr"),
    params:
        contact_source=contact_source_of,
        settings=_canonical({k: v for k, v in config["prediction"].items() if k != "methods"}),
    threads: config["prediction"]["threads"]
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/predictions/{task}/{method}.log",
    benchmark:
        "results/benchmarks/predictions/{task}/{method}.tsv"
    script:
        "../scripts/predict.py"


rule model_checks:
    input:
        shards=train_shards,
        grasp_model="results/models/{task}/grasp_diffuser.pt",
        contact_model="results/models/{task}/contact_diffuser.pt",
        hand="results/hand/hand.npz",
        code=code("models", "data/maps", "data/store", "grasps/expand", "hand"),
    output:
        "results/models/{task}/checks.json",
    params:
        seed=setting("training", "common", "seed"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/models/{task}/checks.log",
    script:
        "../scripts/model_checks.py"
