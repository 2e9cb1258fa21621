# The hand model: the configured backend extracted into MANO-layout arrays, and its picture.


rule hand_model:
    input:
        source=hand_source,
    output:
        "results/hand/hand.npz",
    log:
        "logs/hand/hand_model.log",
    priority: PRIORITY["data"]
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("hand_model.py"),
        model=setting("hand", "model"),
        mano_path=setting("hand", "mano_path"),
        cache_dir=setting("cache_dir"),
    script:
        "../scripts/hand_model.py"


rule hand_figure:
    input:
        hand="results/hand/hand.npz",
    output:
        report(
            "results/figures/hand.png", caption="../report/hand.rst", category="Hand"
        ),
    log:
        "logs/figures/hand.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("hand_figure.py"),
    script:
        "../scripts/hand_figure.py"
