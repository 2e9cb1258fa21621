"""What the 3D viewer (:mod:`tohgs.viz.view`) shows of one task, read from a finished run's ``results/``
folder through the store layer (manifests checked): no viewer library is imported here.

For a task, :class:`TaskResults` opens

- every prediction store ``predictions/<task>/<method>.zarr`` (:func:`tohgs.data.predictions.read_predictions`)
  and, where the method was evaluated, its metric rows ``metrics/<task>/<method>.parquet``;
- the test map shards ``maps/<task>/test/shard-<k>.zarr`` (:func:`tohgs.data.maps.read_map_shard`): the object
  clouds, the distance maps and the ground-truth contact maps of each test configuration;
- the scene stores of the test objects ``scenes/<task>/<object>.zarr`` (:func:`tohgs.data.scenes.read_scenes`),
  the object meshes ``objects/<name>/mesh.obj`` (checked against their recorded checksums), the supports
  ``objects/supports/supports.json`` and the hand ``hand/hand.npz``.

A missing or damaged store fails with the store layer's message (the store's path and the problem); a results
folder without a task's predictions fails naming the folder. Everything returned is in the world frame,
metres: the scene of a configuration (support, base brick, obstacles), the target at its initial or goal
pose, the object cloud and its maps, and each method's hand for a sample index with its metric row.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import trimesh

from tohgs.hand.assets import HandAssets
from tohgs.metrics.tables import QualityThresholds

POSES = ("init", "goal")  # the target's initial pose (where it is picked) and its goal pose (where it is put)
TASKS = ("placing", "stacking", "shelving")
#: The map a cloud is coloured by when none is asked for: the ground truth where a configuration has task grasps.
GROUND_TRUTH = "ground truth contact"
DISTANCE_MAPS = {"distance map D_init": "d_init", "distance map D_goal": "d_goal"}
NO_MAP = "none"


def available_tasks(results_dir: str | Path) -> list[str]:
    """The tasks of ``results_dir`` with prediction stores (``predictions/<task>/*.zarr``), in the paper's order.

    Raises:
        ValueError: the folder is missing or has no prediction store of any task (the message says what to run).
    """
    root = Path(results_dir)
    if not root.is_dir():
        raise ValueError(f"{root}: results folder not found")
    tasks = [t for t in TASKS if any((root / "predictions" / t).glob("*.zarr"))]
    if not tasks:
        raise ValueError(f"{root / 'predictions'}: no prediction stores of any task (<task>/<method>.zarr); "
                         "run the workflow first (make reproduce, or snakemake results/tables/table1.csv)")
    return tasks


def default_labels() -> dict[str, str]:
    """Every built-in method's ``label`` (the schema's default ``methods``)."""
    from tohgs.kinds import schema_default

    return {name: block["label"] for name, block in schema_default("methods").items()}


@dataclass
class MethodResults:
    """One method's predictions of a task and its metric rows.

    Attributes:
        name: the method's config name (the store's ``method`` attribute).
        label: how tables name it.
        arrays: the prediction store's arrays (:mod:`tohgs.data.predictions`).
        attrs: its root attributes.
        rows: ``(object, config_index)`` -> the store's row of that configuration.
        metrics: the metric rows indexed by ``(object, config_index, sample)``, or None where the method was not
            evaluated (no ``metrics/<task>/<method>.parquet``).
        path: the prediction store.
    """

    name: str
    label: str
    arrays: dict[str, np.ndarray]
    attrs: dict[str, Any]
    rows: dict[tuple[str, int], int]
    metrics: pd.DataFrame | None
    path: Path

    @property
    def samples(self) -> int:
        """S, the grasps per configuration."""
        return int(self.arrays["grasp_init"].shape[1])

    @property
    def contact_source(self) -> str | None:
        """What the method's contact maps come from (its config's ``contact`` key: a component, ``ground_truth``
        or ``none``, the hand's own), or None for a method kind without one."""
        return (self.attrs.get("method_config") or {}).get("contact")


@dataclass(frozen=True)
class Part:
    """A mesh of a configuration's scene: ``kind`` is ``support``, ``base``, ``obstacle`` or ``target``; ``mesh``
    in its own frame (shared by every configuration that places the same object) at world ``pose``
    ``[x, y, z, qx, qy, qz, qw]``."""

    kind: str
    name: str
    mesh: trimesh.Trimesh
    pose: np.ndarray

    def world(self) -> trimesh.Trimesh:
        """The mesh in the world frame."""
        from tohgs.geometry.grasp import pose_matrix

        return self.mesh.copy().apply_transform(pose_matrix(self.pose))


@dataclass(frozen=True)
class HandView:
    """One method's grasp of a configuration at a sample index.

    Attributes:
        method, label: the method's name and label.
        sample: the sample index shown (the configuration's sample ``sample`` of the method).
        kept: False for a grasp the method discarded (F-GraspTTA's filter); it is still drawn.
        grasps: ``{"init": (51,), "goal": (51,)}`` the grasp vectors at both poses (world frame).
        vertices: ``{"init": (V, 3), "goal": (V, 3)}`` world-frame hand vertices at both poses, m.
        metrics: the grasp's metric row (``pv`` m^3, ``sd`` m, ``contact_distance`` m, ``init_opp``,
            ``goal_opp`` fractions) or None where the method was not evaluated.
        quality: the QR verdict (PV and SD under the thresholds), None without metrics or for a discarded grasp.
    """

    method: str
    label: str
    sample: int
    kept: bool
    grasps: dict[str, np.ndarray]
    vertices: dict[str, np.ndarray]
    metrics: dict[str, float] | None
    quality: bool | None

    def summary(self) -> str:
        """One line of the grasp's metrics: PV (cm^3), SD (cm), contact distance (cm), Init / Goal OPP (%), QR."""
        if not self.kept:
            return "discarded by the method (not evaluated)"
        m = self.metrics
        if m is None:
            return "not evaluated"
        verdict = "QR pass" if self.quality else "QR fail"
        return (f"PV {m['pv'] * 1e6:.2f} cm³ · SD {m['sd'] * 100:.2f} cm"
                f" · contact {m['contact_distance'] * 100:.2f} cm"
                f" · OPP {m['init_opp'] * 100:.1f} / {m['goal_opp'] * 100:.1f} % · {verdict}")


def _read_metrics(path: Path) -> pd.DataFrame | None:
    """A method's metric rows indexed by (object, config_index, sample); None where the file does not exist."""
    from tohgs.metrics.tables import read_metrics

    if not path.exists():
        return None
    try:
        frame = read_metrics([path])
    except Exception as exc:  # pyarrow's errors for a truncated or foreign file do not name it
        if str(path) in str(exc):
            raise
        raise ValueError(f"{path}: not a readable metric file ({exc})") from exc
    return frame.set_index(["object", "config_index", "sample"]).sort_index()


class TaskResults:
    """One task's predictions, metrics, test configurations and the assets to draw them (module docstring).

    Build it from a results folder with :meth:`from_results`, or from the files themselves (a workflow rule,
    which names its inputs).

    Args:
        task: ``placing``, ``stacking`` or ``shelving``.
        predictions: the task's prediction stores (``predictions/<task>/<method>.zarr``).
        shards: its test map shards (``maps/<task>/test/shard-<k>.zarr``).
        scenes: the scene stores of its test objects (``scenes/<task>/<object>.zarr``).
        objects_dir: the objects stage's folder (``<name>/mesh.obj``).
        supports_json: the supports file (``objects/supports/supports.json``).
        hand: the hand assets, or the hand file (``hand/hand.npz``).
        metrics: metric files (``metrics/<task>/<method>.parquet``); a method without one shows no metrics.
        labels: method name -> label (default: the embedded default config's labels, else the name).
        thresholds: the QR thresholds of the verdict (the config's ``evaluation.qr``).

    Raises:
        ValueError: a missing or damaged store or file (the message names it).
    """

    def __init__(self, task: str, predictions: list[str | Path], shards: list[str | Path], scenes: list[str | Path],
                 objects_dir: str | Path, supports_json: str | Path, hand: HandAssets | str | Path,
                 metrics: list[str | Path] = (), labels: dict[str, str] | None = None,
                 thresholds: QualityThresholds = QualityThresholds()):
        from tohgs.assets.supports import read_supports
        from tohgs.data.maps import read_map_shard
        from tohgs.data.predictions import read_predictions
        from tohgs.data.scenes import read_scenes

        if task not in TASKS:
            raise ValueError(f"unknown task {task!r} (one of {', '.join(TASKS)})")
        self.task = task
        self.thresholds = thresholds
        labels = default_labels() if labels is None else labels
        if not predictions:
            raise ValueError(f"task '{task}': no prediction stores given")
        if not shards:
            raise ValueError(f"task '{task}': no test map shards given")
        self.shards = [read_map_shard(p) for p in shards]
        #: (object, config_index) -> (shard, row) of every test configuration
        self.where: dict[tuple[str, int], tuple[int, int]] = {}
        for k, sh in enumerate(self.shards):
            if sh.attrs.get("task") != task or sh.attrs.get("split") != "test":
                raise ValueError(f"{shards[k]}: a map shard of {sh.attrs.get('task')}/{sh.attrs.get('split')}, "
                                 f"not of {task}/test")
            for row in range(sh.n_configs):
                self.where[(sh.attrs["objects"][int(sh.object_id[row])], int(sh.config_index[row]))] = (k, row)
        metric_files = {Path(p).stem: Path(p) for p in metrics}
        self.methods: dict[str, MethodResults] = {}
        for p in map(Path, predictions):
            arrays, attrs = read_predictions(p)
            if attrs.get("task") != task:
                raise ValueError(f"{p}: a prediction store of task {attrs.get('task')!r}, not {task!r}")
            name = str(attrs["method"])
            vocab = attrs["objects"]
            rows = {(vocab[int(o)], int(c)): i
                    for i, (o, c) in enumerate(zip(arrays["object_id"], arrays["config_index"]))}
            unknown = sorted(set(rows) - set(self.where))
            if unknown:
                raise ValueError(f"{p}: configurations {unknown[:3]} are not in the test map shards of {task}")
            frame = _read_metrics(metric_files[name]) if name in metric_files else None
            self.methods[name] = MethodResults(name, labels.get(name, name), arrays, attrs, rows, frame, p)
        self.methods = dict(sorted(self.methods.items(), key=lambda kv: _method_order(kv[0], list(labels))))
        self.configurations = sorted({key for m in self.methods.values() for key in m.rows})
        if not self.configurations:
            raise ValueError(f"task '{task}': its prediction stores hold no configuration ({predictions[0]}, ...)")
        self.scenes = {}
        for p in scenes:
            sc = read_scenes(p)
            self.scenes[sc.object] = sc
        lacking = sorted({o for o, _ in self.configurations} - set(self.scenes))
        if lacking:
            raise ValueError(f"task '{task}': no scene store of the test objects {', '.join(lacking)} among "
                             f"{[str(p) for p in scenes]}")
        self.objects_dir = Path(objects_dir)
        if not Path(supports_json).is_file():
            raise ValueError(f"{supports_json}: supports file not found (rerun the objects stage)")
        self.supports = read_supports(supports_json)
        self.hand = hand if isinstance(hand, HandAssets) else HandAssets.load(hand)
        self.hand_faces = np.asarray(self.hand.closed_faces)
        self._meshes: dict[str, trimesh.Trimesh] = {}

    @classmethod
    def from_results(cls, results_dir: str | Path, task: str, labels: dict[str, str] | None = None,
                     thresholds: QualityThresholds = QualityThresholds(),
                     hand: HandAssets | None = None) -> "TaskResults":
        """A task of the workflow's ``results/`` folder: every prediction store of the task, the metric files
        beside them, the test shards, the test objects' scene stores, the objects, supports and hand.

        Raises:
            ValueError: the folder, the task's predictions or test shards are missing (the message names the
                folder and what to run), or a store fails its checks.
        """
        root = Path(results_dir)
        if not root.is_dir():
            raise ValueError(f"{root}: results folder not found")
        pred_dir = root / "predictions" / task
        stores = sorted(pred_dir.glob("*.zarr"))
        if not stores:
            raise ValueError(f"{pred_dir}: no prediction stores of task '{task}' (predictions/{task}/<method>.zarr); "
                             "run the workflow's predictions first")
        shard_dir = root / "maps" / task / "test"
        shards = sorted(shard_dir.glob("shard-*.zarr"), key=lambda p: int(p.stem.split("-")[1]))
        if not shards:
            raise ValueError(f"{shard_dir}: no test map shards (shard-<k>.zarr) of task '{task}'")
        from tohgs.data.maps import read_map_shard

        tested = sorted({sh.attrs["objects"][int(o)] for sh in map(read_map_shard, shards) for o in sh.object_id})
        scenes = [root / "scenes" / task / f"{o}.zarr" for o in tested]
        metrics = [p for p in (root / "metrics" / task / f"{s.stem}.parquet" for s in stores) if p.exists()]
        return cls(task, stores, shards, scenes, root / "objects", root / "objects" / "supports" / "supports.json",
                   root / "hand" / "hand.npz" if hand is None else hand, metrics, labels, thresholds)

    # -- what there is ----------------------------------------------------------------------------------------

    @property
    def objects(self) -> list[str]:
        """The test objects with predicted configurations, sorted."""
        return sorted({o for o, _ in self.configurations})

    def configs_of(self, obj: str) -> list[int]:
        """The predicted configurations' indices (in the object's scene store) of ``obj``, sorted."""
        return [c for o, c in self.configurations if o == obj]

    def samples(self, obj: str, c: int) -> int:
        """The most grasps any method predicted for the configuration."""
        return max((m.samples for m in self.methods.values() if (obj, c) in m.rows), default=0)

    def map_names(self) -> list[str]:
        """The maps a cloud can be coloured by: the ground-truth contact map, each method's contact maps, the
        distance maps of the initial and goal scene, and none."""
        return [GROUND_TRUTH, *(f"contact: {m.label}" for m in self.methods.values()), *DISTANCE_MAPS, NO_MAP]

    # -- geometry ---------------------------------------------------------------------------------------------

    def _shard_row(self, obj: str, c: int):
        if (obj, c) not in self.where:
            raise ValueError(f"{self.task}: configuration {c} of {obj!r} is not a test configuration")
        k, row = self.where[(obj, c)]
        return self.shards[k], row

    def target_pose(self, obj: str, c: int, pose: str) -> np.ndarray:
        """(7,) the target's ``[x, y, z, qx, qy, qz, qw]`` at ``pose`` (``init`` or ``goal``)."""
        sc = self.scenes[obj]
        return (sc.target_init_pose if pose == "init" else sc.target_goal_pose)[c]

    def _mesh(self, name: str, support: bool = False) -> trimesh.Trimesh:
        """An object's mesh (checked against its recorded checksum) or a support's, in its own frame, once."""
        from tohgs.assets.mesh import object_mesh

        key = f"support:{name}" if support else name
        if key not in self._meshes:
            self._meshes[key] = self.supports[name].mesh() if support else object_mesh(self.objects_dir, name)
        return self._meshes[key]

    def parts(self, obj: str, c: int) -> list[Part]:
        """The configuration's scene without the target: the support (table or shelf), the base brick
        (Stacking) and the obstacles, placed as :func:`tohgs.geometry.scene.scene_meshes` places them."""
        sc = self.scenes[obj]
        name, pose = sc.support(c)
        out = [Part("support", name, self._mesh(name, support=True), np.asarray(pose))]
        if sc.base(c) is not None:
            name, pose = sc.base(c)
            out.append(Part("base", name, self._mesh(name), np.asarray(pose)))
        return out + [Part("obstacle", o, self._mesh(o), np.asarray(p)) for o, p in sc.obstacles(c)]

    def target_part(self, obj: str, c: int, pose: str) -> Part:
        """The target at ``pose``."""
        return Part("target", obj, self._mesh(obj), np.asarray(self.target_pose(obj, c, pose)))

    def target(self, obj: str, c: int, pose: str) -> trimesh.Trimesh:
        """The target's mesh at ``pose``, world frame."""
        return self.target_part(obj, c, pose).world()

    def cloud(self, obj: str, c: int, pose: str) -> tuple[np.ndarray, np.ndarray]:
        """The object cloud of the configuration's test shard ((N, 3) points, (N, 3) unit normals) at ``pose``,
        world frame: the shard's network-frame points moved by its centroid, then for the goal pose by its
        ``goal_transform``."""
        sh, row = self._shard_row(obj, c)
        pts = sh.points[row].astype(np.float64) + sh.centroid[row]
        nrm = sh.normals[row].astype(np.float64)
        if pose == "goal":
            T = sh.goal_transform[row]
            pts = pts @ T[:3, :3].T + T[:3, 3]
            nrm = nrm @ T[:3, :3].T
        return pts, nrm

    def map_values(self, obj: str, c: int, name: str, sample: int) -> np.ndarray | None:
        """(N,) values in [0, 1] of the map ``name`` (one of :meth:`map_names`) on the cloud, for the sample
        index ``sample`` (a method's sample, or the configuration's task grasp ``sample`` modulo their count);
        None where the configuration has no such map (no task grasp, not predicted by the method) or for
        ``none``."""
        sh, row = self._shard_row(obj, c)
        if name in DISTANCE_MAPS:
            return np.asarray(getattr(sh, DISTANCE_MAPS[name])[row], dtype=np.float64)
        if name == GROUND_TRUTH:
            ids = np.flatnonzero(sh.grasp_config == row)
            return None if not len(ids) else np.asarray(sh.contact[ids[sample % len(ids)]], dtype=np.float64)
        for m in self.methods.values():
            if name == f"contact: {m.label}":
                i = m.rows.get((obj, c))
                if i is None or sample >= m.samples:
                    return None
                return np.asarray(m.arrays["contact"][i, sample], np.float64)
        if name == NO_MAP:
            return None
        raise ValueError(f"unknown map {name!r} (one of {', '.join(self.map_names())})")

    def ground_truth_count(self, obj: str, c: int) -> int:
        """The configuration's task grasps in its test shard (the ground-truth contact maps)."""
        sh, row = self._shard_row(obj, c)
        return int((sh.grasp_config == row).sum())

    def hand_of(self, method: str, obj: str, c: int, sample: int) -> HandView | None:
        """The method's grasp ``sample`` of the configuration, or None where the method did not predict it."""
        m = self.methods[method]
        i = m.rows.get((obj, c))
        if i is None or not 0 <= sample < m.samples:
            return None
        grasps = {pose: np.asarray(m.arrays[f"grasp_{pose}"][i, sample], np.float64) for pose in POSES}
        verts = {pose: self.hand.vertices(g[None])[0] for pose, g in grasps.items()}
        kept = bool(m.arrays["kept"][i, sample])
        metrics, quality = None, None
        if m.metrics is not None and (obj, c, sample) in m.metrics.index:
            row = m.metrics.loc[(obj, c, sample)]
            metrics = {k: float(row[k]) for k in ("pv", "sd", "contact_distance", "init_opp", "goal_opp")}
            if kept and np.isfinite(metrics["pv"]) and np.isfinite(metrics["sd"]):
                quality = bool(metrics["pv"] < self.thresholds.max_pv and metrics["sd"] < self.thresholds.max_sd)
        return HandView(method, m.label, sample, kept, grasps, verts, metrics, quality)

    def hands(self, obj: str, c: int, sample: int) -> list[HandView]:
        """Every method's grasp ``sample`` of the configuration (the methods that predicted it), in method order."""
        return [h for h in (self.hand_of(m, obj, c, sample) for m in self.methods) if h is not None]


def _method_order(name: str, known: list[str]) -> tuple[int, str]:
    """Methods in the config's order (Dataset first in the default), unknown ones (e.g. seed replicas) after."""
    return (known.index(name) if name in known else len(known), name)
