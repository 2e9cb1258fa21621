"""An interactive 3D viewer of a finished run, and its static export (viser).

``python -m tohgs.viz.view results/ --task placing`` serves the viewer on a loopback port
(http://127.0.0.1:8080 by default): a task's test configurations in their initial and goal scenes (support,
base brick, obstacles; the target red), the object's cloud coloured by a contact or distance map, and each
method's grasp at both poses (one colour per method, toggled per method) with its metrics beside it. Its
controls are described in docs/viewer.md. :func:`export_html` writes the same content for a few
configurations as one self-contained HTML file (viser's embedded scene: the client and the scene in the
file, nothing fetched), which the workflow's rule ``viewer`` writes per task and the report links.

The data come from :class:`tohgs.viz.view_data.TaskResults` (the store layer, manifests checked). viser is an
optional dependency: ``pip install -e ".[viewer]"``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from tohgs.metrics.tables import QualityThresholds
from tohgs.hand.assets import HandAssets
from tohgs.viz.view_data import (DISTANCE_MAPS, GROUND_TRUTH, NO_MAP, POSES, HandView, Part, TaskResults,
                                 available_tasks, default_labels)

log = logging.getLogger(__name__)

#: Scene colours (RGB 0-255): the figures' target red, obstacles blue, base green; the support grey.
SCENE_RGB = {"target": (217, 51, 38), "obstacle": (64, 115, 204), "base": (77, 166, 77), "support": (175, 175, 170)}
#: Method colours by the method's place in the config (Dataset skin-coloured, as in the figures), with the
#: name the legend gives them; none is the scene's red, blue or green.
METHOD_RGB: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("skin", (245, 199, 158)), ("orange", (255, 127, 14)), ("purple", (148, 103, 189)), ("pink", (227, 119, 194)),
    ("olive", (188, 189, 34)), ("cyan", (23, 190, 207)), ("brown", (140, 86, 75)), ("gold", (255, 215, 0)),
    ("teal", (0, 128, 128)), ("magenta", (200, 0, 200)), ("lime", (150, 230, 80)), ("slate", (110, 110, 170)),
    ("maroon", (128, 0, 0)), ("black", (40, 40, 40)), ("white", (250, 250, 250)), ("tan", (210, 180, 140)))
SHOWN = 3  # methods whose hands the viewer shows at the start (the first ones: Dataset, Ours, ... by default)
POSE_CHOICES = {"both": POSES, "initial": ("init",), "goal": ("goal",)}
CLOUD_OFFSET = 0.0015  # m along the normals: the cloud sits just outside the target's surface
POINT_SIZE = 0.004  # m
LINE = 0.012  # m between the static export's metric lines
#: The largest static export the report shows: it embeds the file as a base64 data: URL in a frame, and Chromium
#: refuses URLs over 2 MiB (2,097,152 characters, 4/3 of the file).
REPORT_BYTES = 1_500_000
#: The credit a page that draws YCB object models carries (their licence, CC BY 4.0, asks for it).
YCB_CREDIT = ("Object models: the YCB Object and Model Set (Calli et al., IEEE RAM 2015; ycbbenchmarks.com), "
              "CC BY 4.0; rescaled, cleaned and convex-decomposed by tohgs")
EXPORT_FACES = 1500  # most triangles of an object mesh in a static export (:func:`decimated`; docs/viewer.md)


def require_viser():
    """The viser module, or an ImportError that says how to install the viewer's extra."""
    try:
        import viser
    except ImportError as exc:
        raise ImportError('the viewer needs viser, an optional dependency: pip install -e ".[viewer]"') from exc
    return viser


def method_colors(names: list[str], order: list[str]) -> dict[str, tuple[str, tuple[int, int, int]]]:
    """(colour name, RGB) per method: by its place in ``order`` (the config's methods) so that a method keeps
    its colour across tasks; methods not in ``order`` (seed replicas) take the next free colours."""
    out: dict[str, tuple[str, tuple[int, int, int]]] = {}
    taken = {order.index(n) for n in names if n in order}
    spare = (i for i in range(10_000) if i not in taken)
    for n in names:
        i = order.index(n) if n in order else next(spare)
        out[n] = METHOD_RGB[i % len(METHOD_RGB)]
    return out


def map_colors(values: np.ndarray | None, name: str) -> np.ndarray:
    """(N, 3) uint8 colours of a map's values in [0, 1]: inferno for contact maps (1 = touching), viridis for
    distance maps; a uniform grey for no map."""
    import matplotlib

    if values is None:
        return np.full((0, 3), 160, np.uint8)
    cmap = matplotlib.colormaps["viridis" if name in DISTANCE_MAPS else "inferno"]
    return (np.asarray(cmap(np.clip(values, 0.0, 1.0)))[:, :3] * 255).astype(np.uint8)


def camera_for(task: str, looks: list[np.ndarray], distance: float = 0.45) -> tuple[np.ndarray, np.ndarray]:
    """Eye and look-at point (m) that frame ``looks`` (target positions): from the open front of a shelf (-y,
    slightly above) for Shelving, from the front-right and above otherwise, at ``distance`` or farther when
    the targets lie far apart."""
    pts = np.asarray(looks, dtype=np.float64).reshape(-1, 3)
    look = pts.mean(0)
    spread = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    d = np.array([0.0, -1.0, 0.3]) if task == "shelving" else np.array([0.45, -0.75, 0.75])
    return look + max(distance, 1.4 * spread) * d / np.linalg.norm(d), look


def _mesh(scene, name: str, vertices: np.ndarray, faces: np.ndarray, rgb: tuple[int, int, int],
          opacity: float | None = None, **kw) -> Any:
    """A mesh without shadows (they cost software GL several passes a frame and show little here)."""
    return scene.add_mesh_simple(name, np.asarray(vertices, np.float32), np.asarray(faces, np.uint32), color=rgb,
                                 opacity=opacity, cast_shadow=False, receive_shadow=False, **kw)


def decimated(mesh, max_faces: int | None, cache: dict[int, Any] | None = None):
    """``mesh`` with at most ``max_faces`` triangles (open3d's quadric decimation; the mesh itself when it has
    fewer or ``max_faces`` is None), once per mesh object in ``cache``: a static export keeps its size in
    check with objects of tens of thousands of faces, and every placement of an object shares one buffer."""
    if max_faces is None or len(mesh.faces) <= max_faces:
        return mesh
    cache = {} if cache is None else cache
    if id(mesh) not in cache:
        import open3d as o3d
        import trimesh

        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(mesh.vertices, np.float64)),
                                      o3d.utility.Vector3iVector(np.asarray(mesh.faces, np.int32)))
        m = m.simplify_quadric_decimation(target_number_of_triangles=max_faces)
        cache[id(mesh)] = (mesh, trimesh.Trimesh(np.asarray(m.vertices), np.asarray(m.triangles), process=False))
    return cache[id(mesh)][1]


def _part(scene, name: str, part: Part, max_faces: int | None = None, cache: dict[int, Any] | None = None) -> Any:
    """A scene part: its mesh in its own frame (decimated to ``max_faces``, :func:`decimated`) placed at its
    pose (a static export then holds each object's mesh once, however many configurations and poses place it)."""
    q = np.asarray(part.pose[3:], dtype=np.float64)
    mesh = decimated(part.mesh, max_faces, cache)
    return _mesh(scene, name, mesh.vertices, mesh.faces, SCENE_RGB[part.kind], position=tuple(part.pose[:3]),
                 wxyz=(q[3], q[0], q[1], q[2]))


def add_hand(scene, name: str, hand: HandAssets, grasp: np.ndarray, rgb: tuple[int, int, int],
             opacity: float | None = None, visible: bool = True, skinned: bool = False) -> Any:
    """A hand of a (51,) world-frame grasp vector. ``skinned``: the rest mesh skinned by the posed joints
    (viser's skinned mesh, linear blend skinning as :meth:`~tohgs.hand.assets.HandAssets.vertices`: exact for a
    hand without pose blend shapes, such as anny's): every hand then shares one mesh, weights and faces, and
    only its 16 joint frames differ, so a static export of many hands stays small. Otherwise the posed
    vertices."""
    from scipy.spatial.transform import Rotation

    faces = np.asarray(hand.closed_faces)
    if not skinned:
        return _mesh(scene, name, hand.vertices(np.asarray(grasp)[None])[0], faces, rgb, opacity=opacity,
                     visible=visible)
    if hand.pose_dirs is not None:
        raise ValueError(f"hand '{hand.name}' has pose blend shapes: skinning alone would not pose it exactly")
    R, P = hand.joint_frames(np.asarray(grasp)[None])
    joints = np.asarray(hand.rest_joints, dtype=np.float32)
    handle = scene.add_mesh_skinned(
        name, np.asarray(hand.rest_vertices, np.float32), faces.astype(np.uint32),
        bone_wxyzs=np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (len(joints), 1)), bone_positions=joints,
        skin_weights=np.asarray(hand.weights, np.float32), color=rgb, opacity=opacity, cast_shadow=False,
        receive_shadow=False, visible=visible)
    quats = Rotation.from_matrix(R[0]).as_quat()  # (16, 4) xyzw
    for j, bone in enumerate(handle.bones):
        bone.wxyz = (quats[j, 3], quats[j, 0], quats[j, 1], quats[j, 2])
        bone.position = tuple(P[0, j])
    return handle


def configure_scene(scene) -> None:
    """z up, the default lights without shadows."""
    scene.set_up_direction("+z")
    scene.configure_default_lights(True, cast_shadow=False)


def draw_configuration(scene, data: TaskResults, obj: str, c: int, root: str, map_name: str, sample: int = 0,
                       poses: tuple[str, ...] = POSES, max_faces: int | None = None,
                       cache: dict[int, Any] | None = None) -> dict[str, Any]:
    """Add configuration ``c`` of ``obj`` under ``root``: the scene parts, the target and its cloud coloured by
    ``map_name`` at each of ``poses`` (meshes decimated to ``max_faces``, :func:`decimated`). Returns the
    handles by name (``part_<i>``, ``target_<pose>``, ``cloud_<pose>``)."""
    handles: dict[str, Any] = {}
    for i, part in enumerate(data.parts(obj, c)):
        handles[f"part_{i}"] = _part(scene, f"{root}/scene/{part.kind}_{i}", part, max_faces, cache)
    values = data.map_values(obj, c, map_name, sample)
    for pose in poses:
        handles[f"target_{pose}"] = _part(scene, f"{root}/target_{pose}", data.target_part(obj, c, pose), max_faces,
                                          cache)
        if values is not None:
            pts, nrm = data.cloud(obj, c, pose)
            handles[f"cloud_{pose}"] = scene.add_point_cloud(
                f"{root}/cloud_{pose}", (pts + CLOUD_OFFSET * nrm).astype(np.float32), map_colors(values, map_name),
                point_size=POINT_SIZE, point_shape="circle", precision="float32")
    return handles


def _hand_label(h: HandView) -> str:
    verdict = "" if h.quality is None else (" ✓ QR" if h.quality else " ✗ QR")
    return f"{h.label}{'' if h.kept else ' (discarded)'}{verdict}"


class Viewer:
    """The interactive viewer of a results folder (module docstring; controls in docs/viewer.md).

    Args:
        results_dir: the workflow's ``results/`` folder.
        task: the task shown first (default: the first with predictions).
        host, port: where to serve (loopback by default; port 0: any free port).
        labels: method name -> label (default: the embedded default config's).
        thresholds: the QR verdict's thresholds.
        shown: the methods whose hands are shown at the start (default: the first :data:`SHOWN` of each task;
            the others are a checkbox away).

    Raises:
        ValueError: a missing results folder or store, or a store that fails its checks.
    """

    def __init__(self, results_dir: str | Path, task: str | None = None, host: str = "127.0.0.1", port: int = 8080,
                 labels: dict[str, str] | None = None, thresholds: QualityThresholds = QualityThresholds(),
                 shown: list[str] | None = None):
        viser = require_viser()
        self.results_dir = Path(results_dir)
        self.tasks = available_tasks(self.results_dir)
        if task is not None and task not in self.tasks:
            raise ValueError(f"{self.results_dir / 'predictions' / task}: no prediction stores of task '{task}' "
                             f"(this results folder has {', '.join(self.tasks)})")
        self.labels = default_labels() if labels is None else labels
        self.thresholds = thresholds
        self.shown = shown
        self._cache: dict[str, TaskResults] = {}
        self.data = self._load(task or self.tasks[0])  # before the server: a bad store fails without one
        self._lock = threading.RLock()
        self._quiet = False  # set while the viewer itself changes controls (their callbacks then do nothing)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        configure_scene(self.server.scene)
        self.server.gui.configure_theme(control_width="large")
        self._method_boxes: dict[str, Any] = {}
        self._handles: dict[str, Any] = {}
        self._build_gui()
        with self._lock:
            self._show_task(self.data.task, aim=True)

    # -- set-up -----------------------------------------------------------------------------------------------

    def _load(self, task: str) -> TaskResults:
        if task not in self._cache:
            t0 = time.perf_counter()
            hand = next(iter(self._cache.values())).hand if self._cache else None
            self._cache[task] = TaskResults.from_results(self.results_dir, task, self.labels, self.thresholds,
                                                         hand=hand)
            log.info("%s: loaded in %.1f s", task, time.perf_counter() - t0)
        return self._cache[task]

    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.add_markdown(f"**tohgs** results: `{self.results_dir}`")
        if any(o.startswith("ycb-") for o in self.data.objects):
            gui.add_markdown(YCB_CREDIT)
        self.task = gui.add_dropdown("Task", self.tasks, initial_value=self.data.task,
                                     hint="The task whose test configurations are shown")
        self.object = gui.add_dropdown("Object", self.data.objects, hint="The test object (the target)")
        self.config = gui.add_dropdown("Configuration", ["0"], hint="The test configuration of the object (its "
                                       "index in the object's scene store)")
        self.grasp = gui.add_slider("Grasp", 0, 1, 1, 0, hint="The sample index: each method's grasp of that index "
                                    "(and of the ground-truth contact maps, the task grasp of that index)")
        self.pose = gui.add_dropdown("Pose", tuple(POSE_CHOICES), initial_value="both",
                                     hint="The target and the hands at the initial pose, the goal pose or both")
        self.map = gui.add_dropdown("Colour", self.data.map_names(), initial_value=GROUND_TRUTH,
                                    hint="The map the object's cloud is coloured by")
        self.show_labels = gui.add_checkbox("Labels", True, hint="Each hand's method and QR verdict in the scene")
        self.aim = gui.add_button("Look at the target", hint="Move the camera back onto the target")
        self.metrics = gui.add_html("")
        self.methods_folder = gui.add_folder("Methods")
        self.task.on_update(lambda _: self._on(self._show_task, self.task.value, aim=True))
        self.object.on_update(lambda _: self._on(self._show_object, aim=True))
        self.config.on_update(lambda _: self._on(self._show_config, aim=True))
        self.grasp.on_update(lambda _: self._on(self._show_grasp))
        self.pose.on_update(lambda _: self._on(self._show_config, aim=True))
        self.map.on_update(lambda _: self._on(self._show_config))
        self.show_labels.on_update(lambda _: self._on(self._show_grasp))
        self.aim.on_click(lambda _: self._on(self._aim))

    def _on(self, fn, *args, **kwargs) -> None:
        """Run a control's callback unless the viewer itself is changing the controls."""
        if self._quiet:
            return
        with self._lock:
            fn(*args, **kwargs)

    def _set(self, handle, **props) -> None:
        """Change a control's properties without running its callback."""
        self._quiet = True
        try:
            for k, v in props.items():
                setattr(handle, k, v)
        finally:
            self._quiet = False

    # -- what is shown ----------------------------------------------------------------------------------------

    @property
    def url(self) -> str:
        """The address the viewer is served at."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def _show_task(self, task: str, aim: bool = False) -> None:
        self.data = self._load(task)
        for box in self._method_boxes.values():
            box.remove()
        self._method_boxes = {}
        self.colors = method_colors(list(self.data.methods), list(self.labels))
        with self.methods_folder:
            for k, (name, m) in enumerate(self.data.methods.items()):
                cname = self.colors[name][0]
                on = k < SHOWN if self.shown is None else name in self.shown
                box = self.server.gui.add_checkbox(f"{m.label} ({cname})", on,
                                                   hint=f"Show {m.label}'s hands ({cname}); method '{name}'")
                box.on_update(lambda _, n=name: self._on(self._toggle_method, n))
                self._method_boxes[name] = box
        map_value = self.map.value if self.map.value in self.data.map_names() else GROUND_TRUTH
        self._set(self.map, options=self.data.map_names(), value=map_value)
        self._set(self.object, options=self.data.objects, value=self.data.objects[0])
        self._show_object(aim=aim)

    def _show_object(self, aim: bool = False) -> None:
        configs = [str(c) for c in self.data.configs_of(self.object.value)]
        self._set(self.config, options=configs, value=configs[0])
        self._show_config(aim=aim)

    @property
    def key(self) -> tuple[str, int]:
        """The shown configuration: (object, config_index)."""
        return self.object.value, int(self.config.value)

    @property
    def poses(self) -> tuple[str, ...]:
        return POSE_CHOICES[self.pose.value]

    def _show_config(self, aim: bool = False) -> None:
        obj, c = self.key
        s = self.data.samples(obj, c)
        self._set(self.grasp, max=max(1, s - 1), value=min(int(self.grasp.value), max(0, s - 1)), disabled=s <= 1)
        self.server.scene.remove_by_name("/config")
        draw_configuration(self.server.scene, self.data, obj, c, "/config", NO_MAP, 0, self.poses)
        self._show_grasp()
        if aim:
            self._aim()

    def _show_grasp(self) -> None:
        obj, c = self.key
        sample = int(self.grasp.value)
        scene = self.server.scene
        scene.remove_by_name("/clouds")
        values = self.data.map_values(obj, c, self.map.value, sample)
        for pose in self.poses if values is not None else ():
            pts, nrm = self.data.cloud(obj, c, pose)
            scene.add_point_cloud(f"/clouds/{pose}", (pts + CLOUD_OFFSET * nrm).astype(np.float32),
                                  map_colors(values, self.map.value), point_size=POINT_SIZE, point_shape="circle",
                                  precision="float32")
        scene.remove_by_name("/hands")
        hands = self.data.hands(obj, c, sample)
        for h in hands:
            rgb = self.colors[h.method][1]
            for pose in self.poses:
                v = h.vertices[pose]
                _mesh(scene, f"/hands/{h.method}/{pose}", v, self.data.hand_faces, rgb,
                      opacity=None if h.kept else 0.45, visible=self._method_boxes[h.method].value)
                if self.show_labels.value:
                    scene.add_label(f"/hands/{h.method}/{pose}_label", _hand_label(h),
                                    position=tuple(v[np.argmax(v[:, 2])] + np.array([0, 0, 0.01])),
                                    visible=self._method_boxes[h.method].value, font_screen_scale=0.7)
        self._hands = {h.method: h for h in hands}
        self.metrics.content = self._metrics_html(obj, c, sample, hands)

    def _toggle_method(self, name: str) -> None:
        visible = self._method_boxes[name].value
        for pose in POSES:
            for suffix in ("", "_label"):
                handle = self.server.scene.get_handle_by_name(f"/hands/{name}/{pose}{suffix}")
                if handle is not None:
                    handle.visible = visible

    def _metrics_html(self, obj: str, c: int, sample: int, hands: list[HandView]) -> str:
        """The metrics table of the shown grasps: one row per method, its colour beside it."""
        gt = self.data.ground_truth_count(obj, c)
        rows = []
        for h in hands:
            name, rgb = self.colors[h.method]
            m = h.metrics
            swatch = ('<span style="display:inline-block;width:0.8em;height:0.8em;'
                      f'background:rgb{rgb};border:1px solid #888"></span>')
            if m is None or not h.kept:
                cells = f'<td colspan="6">{"discarded by the method" if not h.kept else "not evaluated"}</td>'
            else:
                qr = "—" if h.quality is None else ("✓" if h.quality else "✗")
                values = (f"{m['pv'] * 1e6:.2f}", f"{m['sd'] * 100:.2f}", f"{m['contact_distance'] * 100:.2f}",
                          f"{m['init_opp'] * 100:.1f}", f"{m['goal_opp'] * 100:.1f}", qr)
                cells = "".join(f"<td>{v}</td>" for v in values)
            rows.append(f"<tr><td>{swatch} {h.label}</td>{cells}</tr>")
        missing = [m.label for n, m in self.data.methods.items() if n not in {h.method for h in hands}]
        t = self.thresholds
        return (f'<div style="font-size:0.8em"><b>{self.data.task}: {obj} #{c}, grasp {sample}</b> '
                f"({gt} ground-truth task grasps)"
                '<table style="border-collapse:collapse;width:100%;text-align:right">'
                "<tr><th style='text-align:left'>method</th><th>PV cm³</th><th>SD cm</th><th>contact cm</th>"
                "<th>Init OPP %</th><th>Goal OPP %</th><th>QR</th></tr>" + "".join(rows) + "</table>"
                f"QR: PV &lt; {t.max_pv * 1e6:g} cm³ and SD &lt; {t.max_sd * 100:g} cm."
                + (f" Not predicted here: {', '.join(missing)}." if missing else "") + "</div>")

    def _aim(self) -> None:
        obj, c = self.key
        eye, look = camera_for(self.data.task, [self.data.target_pose(obj, c, p)[:3] for p in self.poses])
        self.server.initial_camera.position = tuple(eye)
        self.server.initial_camera.look_at = tuple(look)
        self.server.initial_camera.up = (0.0, 0.0, 1.0)
        for client in self.server.get_clients().values():
            with client.atomic():
                client.camera.position = tuple(eye)
                client.camera.look_at = tuple(look)

    def stop(self) -> None:
        """Stop the server."""
        self.server.stop()


def _spread(configurations: list[tuple[str, int]], n: int) -> list[tuple[str, int]]:
    """Up to ``n`` configurations, one per object first, then round-robin."""
    by_obj: dict[str, list[tuple[str, int]]] = {}
    for key in configurations:
        by_obj.setdefault(key[0], []).append(key)
    out: list[tuple[str, int]] = []
    k = 0
    while len(out) < n and any(k < len(v) for v in by_obj.values()):
        out += [v[k] for v in by_obj.values() if k < len(v)][: n - len(out)]
        k += 1
    return out


def export_html(data: TaskResults, out: str | Path, configs: int = 4, samples: int = 1,
                methods: list[str] | None = None, skinned: bool | None = None,
                max_faces: int | None = EXPORT_FACES) -> dict[str, Any]:
    """Write one self-contained HTML file (viser's embedded scene) of a task: ``configs`` test configurations
    (one per object first) side by side along x, each with its scene, the target at both poses and its cloud
    coloured by the ground-truth contact map (else the first method's), and the first ``samples`` grasps of
    each of ``methods`` (default: all) at both poses with a label of each grasp's metrics. The first
    :data:`SHOWN` methods are visible at the start; the scene tree of the page (its top-right button) shows and
    hides each method (``/hands/<method>``). ``skinned`` (default: where exact, a hand without pose blend
    shapes) sends the hands as one skinned mesh and joint frames each (:func:`add_hand`), otherwise vertex by
    vertex. Object meshes of more than ``max_faces`` triangles are decimated to that (the scene is context;
    the live viewer draws them whole). Returns what was drawn (configurations, methods, hands, bytes); a file
    over :data:`REPORT_BYTES` is logged as a warning, since the report shows it in a frame of a ``data:`` URL,
    which Chromium caps at 2 MB.
    """
    from tohgs.io import atomic_path

    viser = require_viser()
    names = [m for m in (methods or list(data.methods)) if m in data.methods]
    missing = sorted(set(methods or []) - set(data.methods))
    if missing:
        raise ValueError(f"task '{data.task}': no prediction store of {', '.join(missing)} among the inputs")
    picks = _spread(data.configurations, configs)
    skinned = data.hand.pose_dirs is None if skinned is None else skinned
    cache: dict[int, Any] = {}
    colors = method_colors(names, list(default_labels()))
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    hands = 0
    try:
        scene = server.scene
        configure_scene(scene)
        parts = [[p.world() for p in data.parts(o, c)] for o, c in picks]
        lo = np.min([m.bounds[0] for ms in parts for m in ms], axis=0)
        hi = np.max([m.bounds[1] for ms in parts for m in ms], axis=0)
        step = float(hi[0] - lo[0]) + 0.3  # configurations side by side along x, 30 cm apart
        for k, (obj, c) in enumerate(picks):
            offset = (k * step, 0.0, 0.0)
            cell = f"/configs/{obj}_{c}"
            scene.add_frame(cell, show_axes=False, position=offset)
            map_name = GROUND_TRUTH if data.ground_truth_count(obj, c) else f"contact: {data.methods[names[0]].label}"
            draw_configuration(scene, data, obj, c, cell, map_name, max_faces=max_faces, cache=cache)
            top = max(float(data.target(obj, c, p).bounds[1][2]) for p in POSES)
            for pose in POSES:
                p = data.target_pose(obj, c, pose)[:3]
                scene.add_label(f"{cell}/label_{pose}", f"{obj} #{c}: {'initial' if pose == 'init' else 'goal'} pose",
                                position=(p[0], p[1], top + 0.08), font_screen_scale=0.8)
            right = max(float(data.target(obj, c, p).bounds[1][0]) for p in POSES) + 0.08
            y = float(np.mean([data.target_pose(obj, c, p)[1] for p in POSES]))
            row = 0
            for k, name in enumerate(names):
                frame = f"/hands/{name}/{obj}_{c}"
                scene.add_frame(frame, show_axes=False, position=offset, visible=k < SHOWN)
                for s in range(samples):
                    h = data.hand_of(name, obj, c, s)
                    if h is None:
                        continue
                    for pose in POSES:
                        add_hand(scene, f"{frame}/{s}_{pose}", data.hand, h.grasps[pose], colors[name][1],
                                 opacity=None if h.kept else 0.45, skinned=skinned)
                        hands += 1
                    # a column of metric lines beside the targets, in scene units: they never overlap
                    scene.add_label(f"{frame}/{s}_metrics", f"{h.label} ({colors[name][0]}) #{s}: {h.summary()}",
                                    position=(right, y, top + 0.02 - LINE * row), font_size_mode="scene",
                                    font_scene_height=0.6 * LINE, anchor="center-left")
                    row += 1
        eye, look = camera_for(data.task, [data.target_pose(picks[0][0], picks[0][1], p)[:3] for p in POSES])
        server.initial_camera.position = tuple(eye)
        server.initial_camera.look_at = tuple(look)
        server.initial_camera.up = (0.0, 0.0, 1.0)
        html = scene.as_html()
    finally:
        server.stop()
    if any(o.startswith("ycb-") for o, _ in picks):
        credit = (f'<div style="position:fixed;left:6px;bottom:4px;z-index:1000;font:11px sans-serif;color:#444;'
                  f'background:rgba(255,255,255,0.7)">{YCB_CREDIT}</div>')
        html = html.replace("</body>", credit + "</body>", 1) if "</body>" in html else html + credit
    with atomic_path(out) as tmp:
        Path(tmp).write_text(html)
    info = {"task": data.task, "configurations": [f"{o} #{c}" for o, c in picks], "methods": names, "hands": hands,
            "bytes": len(html.encode())}
    log.info("wrote %s: %s", out, info)
    if info["bytes"] > REPORT_BYTES:
        log.warning("%s: %.1f MB, over the %.1f MB that the report's frame (a data: URL) shows in Chromium: open the "
                    "file itself (fewer figures.viewer.configs or samples make it smaller)", out, info["bytes"] / 1e6,
                    REPORT_BYTES / 1e6)
    return info


def main(argv: list[str] | None = None) -> int:
    """``python -m tohgs.viz.view RESULTS [--task T] [--port P] [--host H] [--stop-after S] [--configfile F]``."""
    parser = argparse.ArgumentParser(prog="python -m tohgs.viz.view", description=(
        "Serve an interactive 3D viewer of a finished run's results (scenes, contact maps, every method's grasps "
        "at both poses); or, with --export, write one task's static HTML file."))
    parser.add_argument("results", help="the workflow's results folder (results/)")
    parser.add_argument("--task", choices=("placing", "stacking", "shelving"), help="the task shown first")
    parser.add_argument("--host", default="127.0.0.1", help="the address to serve at (default: loopback only)")
    parser.add_argument("--port", type=int, default=8080, help="the port (0: any free port; a busy port: the next)")
    parser.add_argument("--stop-after", type=float, default=None, metavar="SECONDS",
                        help="stop the server after this many seconds (default: run until interrupted)")
    parser.add_argument("--configfile", default=None,
                        help="the run's config file, for the methods' labels and the QR thresholds (default: the "
                             "embedded default config)")
    parser.add_argument("--methods", nargs="+", default=None, metavar="METHOD",
                        help=f"the methods shown at the start (default: the first {SHOWN}; each has a checkbox)")
    parser.add_argument("--export", default=None, metavar="HTML", help="write the static HTML of --task and exit")
    parser.add_argument("--configs", type=int, default=4, help="with --export: configurations drawn")
    parser.add_argument("--samples", type=int, default=1, help="with --export: grasps per method and configuration")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("websockets").setLevel(logging.WARNING)  # not every connection
    try:
        labels, thresholds = None, QualityThresholds()
        if args.configfile:
            from tohgs.config import load_config

            cfg = load_config(args.configfile)
            labels = {n: b["label"] for n, b in cfg["methods"].items()}
            thresholds = QualityThresholds(**cfg["evaluation"]["qr"])
        if args.export:
            task = args.task or available_tasks(args.results)[0]
            export_html(TaskResults.from_results(args.results, task, labels, thresholds), args.export, args.configs,
                        args.samples)
            return 0
        t0 = time.perf_counter()
        viewer = Viewer(args.results, args.task, args.host, args.port, labels, thresholds, args.methods)
    except (ValueError, ImportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"tohgs viewer of {args.results} at {viewer.url} (ready in {time.perf_counter() - t0:.1f} s; "
          "Ctrl+C stops it)", flush=True)
    try:
        if args.stop_after is None:
            while True:
                time.sleep(3600)
        time.sleep(args.stop_after)
    except KeyboardInterrupt:
        pass
    finally:
        viewer.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
