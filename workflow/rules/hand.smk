# The hand model: the configured backend extracted into MANO-layout arrays, and its picture.


rule hand_model:
    input:
        source=hand_source,
        code=code("hand_model.py"),
    output:
        "results/hand/hand.npz",
    params:
        model=setting("hand", "model"),
        mano_path=setting("hand", "mano_path"),
        cache_dir=setting("cache_dir"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/hand/hand_model.log",
    script:
        "../scripts/hand_model.py"


rule hand_figure:
    input:
        hand="results/hand/hand.npz",
        code=code("hand_figure.py"),
    output:
        report("results/figures/hand.png", caption="../report/hand.rst", category="Hand"),
    conda:
        "../envs/tohgs.yaml"
    log:
        "logs/figures/hand.log",
    script:
        "../scripts/hand_figure.py"
