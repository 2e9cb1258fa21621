# Evaluation: per-grasp metrics per task and method, the tables of the config (each with its QR grid), and
# the qualitative figures (predicted hands in their scenes, contact maps next to the truth).


rule evaluate:
    input:
        predictions="results/predictions/{task}/{method}.zarr",
        scenes=test_scene_stores,
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
    output:
        "results/metrics/{task}/{method}.parquet",
    log:
        "logs/metrics/{task}/{method}.log",
    benchmark:
        "results/benchmarks/metrics/{task}/{method}.tsv"
    conda:
        "../envs/tohgs.yaml"
    threads: config["evaluation"]["threads"]
    resources:
        **rule_resources("evaluate"),
    params:
        code=code("evaluate.py"),
        objects_dir=objects_dir_of_supports,
        sd=evaluation_sd_settings(),
        voxel_pitch=setting("metrics", "voxel_pitch"),
        cache_dir=setting("cache_dir"),
        robust_sd=robust_sd_settings,
        palm_sd=palm_sd_of,
        pv_mesh=setting("evaluation", "pv_mesh"),
        sd_hand=setting("evaluation", "sd_hand"),
    script:
        "../scripts/evaluate.py"


rule table:
    input:
        metrics=table_metrics,
    output:
        csv=report(
            "results/tables/{table}.csv",
            caption="../report/table.rst",
            category="Tables",
        ),
        md="results/tables/{table}.md",
        grid=report(
            "results/tables/{table}_qr_grid.csv",
            caption="../report/qr_grid.rst",
            category="Tables",
        ),
    log:
        "logs/tables/{table}.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("table.py"),
        tasks=setting("scenes", "tasks"),
        rows=lambda w: setting("tables", w.table, "rows"),
        labels=lambda w: {
            m: TABLES[w.table]["labels"].get(m, METHODS[m]["label"])
            for m in TABLES[w.table]["rows"]
        },
        pending=lambda w: setting("tables", w.table, "pending"),
        columns=lambda w: setting("tables", w.table, "columns"),
        paper=lambda w: setting("tables", w.table, "paper"),
        replicas=lambda w: replicas_of(TABLES[w.table]["rows"]),
        qr=setting("evaluation", "qr"),
        qr_grid=setting("evaluation", "qr_grid"),
        bootstrap=setting("evaluation", "bootstrap"),
    script:
        "../scripts/table.py"


rule claims:
    input:
        metrics=claims_metrics,
    output:
        csv=report(
            "results/tables/claims.csv",
            caption="../report/claims.rst",
            category="Tables",
        ),
        md="results/tables/claims.md",
    log:
        "logs/tables/claims.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("claims.py"),
        tasks=setting("scenes", "tasks"),
        claims=setting("claims"),
        tables=lambda w: {
            name: {"rows": t["rows"]} for name, t in sorted(TABLES.items())
        },
        labels=lambda w: {m: METHODS[m]["label"] for m in claims_methods()},
        replicas=lambda w: replicas_of(claims_methods()),
        qr=setting("evaluation", "qr"),
        bootstrap=setting("evaluation", "bootstrap"),
    script:
        "../scripts/claims.py"


rule predictions_figure:
    input:
        predictions=lambda w: expand(
            "results/predictions/{task}/{method}.zarr",
            task=w.task,
            method=figure_methods(w),
        ),
        scenes=test_scene_stores,
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
    output:
        report(
            "results/figures/predictions_{task}.png",
            caption="../report/predictions.rst",
            category="Evaluation",
        ),
    log:
        "logs/figures/predictions_{task}.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("predictions_figure.py"),
        objects_dir=objects_dir_of_supports,
        configs=setting("figures", "prediction_configs"),
        labels=lambda w: [METHODS[m]["label"] for m in figure_methods(w)],
    script:
        "../scripts/predictions_figure.py"


# figures.comparisons: the same figure of the comparison's methods (figure_methods reads the name)
use rule predictions_figure as comparison_figure with:
    output:
        report(
            "results/figures/compare_{name}_{task}.png",
            caption="../report/predictions.rst",
            category="Evaluation",
        ),
    log:
        "logs/figures/compare_{name}_{task}.log",


rule contact_maps_figure:
    input:
        predictions=expand(
            "results/predictions/{task}/{method}.zarr",
            task=config["scenes"]["tasks"],
            method=config["figures"]["contact_methods"],
        ),
        shards=all_test_shards,
    output:
        report(
            "results/figures/contact_maps.png",
            caption="../report/contact_maps.rst",
            category="Evaluation",
        ),
    log:
        "logs/figures/contact_maps.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("contact_maps_figure.py"),
        configs=setting("figures", "prediction_configs"),
        labels=lambda w: {
            m: METHODS[m]["label"] for m in config["figures"]["contact_methods"]
        },
    script:
        "../scripts/contact_maps_figure.py"
