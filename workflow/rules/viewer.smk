# The 3D viewer's static export: one self-contained HTML file per task (viser's embedded scene: the client and
# the scene in the file), linked from the report. The interactive viewer is `python -m tohgs.viz.view results/`.


rule viewer:
    input:
        predictions=viewer_predictions,
        metrics=viewer_metrics,
        shards=test_shards,
        scenes=test_scene_stores,
        objects=object_dirs(),
        supports="results/objects/supports",
        hand="results/hand/hand.npz",
    output:
        report(
            "results/viewer/{task}.html",
            caption="../report/viewer.rst",
            category="Viewer",
        ),
    log:
        "logs/figures/viewer_{task}.log",
    conda:
        "../envs/tohgs.yaml"
    params:
        code=code("viewer_export.py"),
        objects_dir=objects_dir_of_supports,
        labels=viewer_labels,
        qr=setting("evaluation", "qr"),
        configs=setting("figures", "viewer", "configs"),
        samples=setting("figures", "viewer", "samples"),
    script:
        "../scripts/viewer_export.py"
