# The hand model: the configured backend extracted into MANO-layout arrays, and its picture.


rule hand_model:
    input:
        source=hand_source,
    output:
        "results/hand/hand.npz",
    params:
        code=code("hand_model.py"),
        model=setting("hand", "model"),
        mano_path=setting("hand", "mano_path"),
        cache_dir=setting("cache_dir"),
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/hand/hand_model.log",
    script:
        "../scripts/hand_model.py"


rule hand_figure:
    input:
        hand="results/hand/hand.npz",
    output:
        report("results/figures/hand.png", caption="../report/hand.rst", category="Hand"),
    params:
        code=code("hand_figure.py"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/figures/hand.log",
    script:
        "../scripts/hand_figure.py"
