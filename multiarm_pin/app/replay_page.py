"""The offline replay page built in this process: Meshcat's scene tree without its server.

meshcat 0.3.2 writes a static page (``Visualizer.static_html``) by asking its server, a
subprocess reached over ZMQ, for the scene. The server keeps a tree of nodes, one per path;
each node holds the last packed ``set_object`` (which clears the node's properties), its
``set_property`` packets in order, the last ``set_transform`` and the last ``set_animation``.
It writes them node by node, in the tree's order, as base64 ``fetch`` commands into a page
that inlines the viewer's ``main.min.js`` (``handle_zmq`` in ``meshcat/servers/zmqserver.py``).

:class:`PageWindow` is a window for ``meshcat.Visualizer`` that keeps the same tree here, so
writing ``replay.html`` starts no server process and makes no ZMQ round trip per command.
Commands are packed by ``msgpack``'s C packer into the bytes of meshcat's own pure-Python
``umsgpack.packb`` (same types, same encodings; the tests compare the two packers and the
two pages byte for byte). It writes one of two pages:

- ``compact=False``: the server's page, character for character;
- ``compact=True`` (the replay's): the same commands in the same order, but each distinct
  triangle mesh (:class:`~multiarm_pin.app.replay_meshes.CompactMesh`) held once however
  many nodes show it, all of it in one zlib-compressed binary block that the page inflates
  (the browser's ``DecompressionStream``) before it hands each command to the viewer
  (``viewer.handle_command_bytearray``, in order), plus the overlay of
  :mod:`multiarm_pin.app.replay_overlay` (simulated time, legend, contact timeline).

A mesh in the block: its vertices renumbered in order of first use by the faces, quantised
to 16 bits per axis over its bounding box (error at most ``extent / 131070`` per axis: a few
micrometres for an arm's link) and stored as differences of consecutive vertices (modulo
2^16); its faces' vertex indices as differences of consecutive indices (modulo 2^16, or
2^32 from 65536 vertices on). :func:`decode_block` reads a page back (the tests use it).
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import re
import zlib
from dataclasses import dataclass

import meshcat
import msgpack
import numpy as np
import umsgpack
from meshcat.commands import SetObject
from meshcat.servers.tree import SceneTree, find_node, walk
from meshcat.servers.zmqserver import MESHCAT_COMMANDS, VIEWER_ROOT, create_command

from multiarm_pin.app import replay_overlay
from multiarm_pin.app.replay_meshes import CompactMesh

# The page of meshcat 0.3.2's server (``handle_zmq``, command ``get_scene``), character for
# character: the viewer's script, then the scene's drawing commands.
_PAGE = """
                <!DOCTYPE html>
                <html>
                    <head> <meta charset=utf-8> <title>MeshCat</title> </head>
                    <body>
                        <div id="meshcat-pane">
                        </div>
                        <script>
                            {mainminjs}
                        </script>
                        <script>
                            var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
                            {commands}
                        </script>
                         <style>
                            body {{margin: 0; }}
                            #meshcat-pane {{
                                width: 100vw;
                                height: 100vh;
                                overflow: hidden;
                            }}
                        </style>
                        <script id="embedded-json"></script>
                    </body>
                </html>
            """  # noqa: E501

# The compact page: the same viewer, one data block, the overlay. ``{{``: a literal brace.
_COMPACT_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset=utf-8><title>{title}</title>
<style>
body {{margin: 0; }}
#meshcat-pane {{width: 100vw; height: 100vh; overflow: hidden; }}
#multiarm-error {{display: none; position: absolute; left: 30%; top: 40%; padding: 10px;
  background: #8b0000; color: #fff; font: 14px sans-serif; z-index: 20; }}
{overlay_css}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="multiarm-error"></div>
{overlay_html}
<script>
{mainminjs}
</script>
<script id="multiarm-manifest" type="application/json">{manifest}</script>
<script id="multiarm-block" type="application/octet-stream">{block}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
{loader_js}
{overlay_js}
</script>
</body>
</html>
"""

# Inflates the block, builds each distinct mesh once, puts it at its nodes, then hands every
# command to the viewer in the page's order. ``multiarmReplay.ready`` resolves when done.
_LOADER_JS = r"""
var multiarmReplay = (function () {
  "use strict";
  const THREE = MeshCat.THREE;
  const manifest = JSON.parse(document.getElementById("multiarm-manifest").textContent);
  function fromBase64(text) {
    const bin = atob(text.trim());
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }
  async function inflate(bytes) {
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }
  function view(data, Type, part) {  // a copy: aligned for the typed array
    return new Type(data.slice(part[0], part[0] + part[1]).buffer);
  }
  function geometry(data, m) {
    const n = m.vertices, d = view(data, Uint16Array, m.positions);
    const pos = new Float32Array(3 * n);
    for (let a = 0; a < 3; a++) {
      let acc = 0;
      for (let i = 0; i < n; i++) {
        acc = (acc + d[a * n + i]) & 0xFFFF;
        pos[3 * i + a] = m.low[a] + m.step[a] * acc;
      }
    }
    let index;
    if (m.index_bits === 16) {
      const di = view(data, Uint16Array, m.index);
      index = new Uint16Array(di.length);
      let acc = 0;
      for (let i = 0; i < di.length; i++) { acc = (acc + di[i]) & 0xFFFF; index[i] = acc; }
    } else {
      const di = view(data, Uint32Array, m.index);
      index = new Uint32Array(di.length);
      let acc = 0;
      for (let i = 0; i < di.length; i++) { acc = (acc + di[i]) >>> 0; index[i] = acc; }
    }
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(pos, 3));
    geo.setIndex(new THREE.BufferAttribute(index, 1));
    if (m.groups.length > 1) {
      m.groups.forEach((g, k) => geo.addGroup(3 * g[0], 3 * g[1], k));
    }
    geo.computeVertexNormals();
    return geo;
  }
  function split(path) { return path.split("/").filter(x => x.length > 0); }
  async function load() {
    const data = await inflate(fromBase64(document.getElementById("multiarm-block").textContent));
    const geometries = manifest.meshes.map(m => geometry(data, m));
    const loader = new THREE.MaterialLoader();
    const materials = manifest.materials.map(json => loader.parse(json));
    for (const [path, g, mats] of manifest.nodes) {
      const mat = mats.length === 1 ? materials[mats[0]] : mats.map(k => materials[k]);
      const mesh = new THREE.Mesh(geometries[g], mat);
      mesh.castShadow = true;
      mesh.receiveShadow = true;
      viewer.set_object(split(path), mesh);
    }
    for (const part of manifest.commands) {
      viewer.handle_command_bytearray(data.slice(part[0], part[0] + part[1]));
    }
    viewer.set_dirty();
    return manifest;
  }
  const ready = load();
  ready.catch(err => {
    const box = document.getElementById("multiarm-error");
    if (box) {
      box.textContent = "the replay could not be loaded: " + err +
        (typeof DecompressionStream === "undefined" ?
         " (this browser has no DecompressionStream: use Chrome or Edge 80+, Firefox 113+, " +
         "Safari 16.4+)" : "");
      box.style.display = "block";
    }
    console.error(err);
  });
  return {ready: ready, manifest: manifest};
})();
"""


def _ext(obj):
    if isinstance(obj, umsgpack.Ext):
        return msgpack.ExtType(obj.type, obj.data)
    raise TypeError(f"cannot pack {type(obj).__name__} for Meshcat")


def pack(data) -> bytes:
    """``umsgpack.packb(data)`` (meshcat's packer) computed by msgpack's C packer.

    Args:
        data: a lowered Meshcat command: dicts, lists, tuples, str, bytes, bool, int, float
            (numpy float64 included), None and ``umsgpack.Ext``.
    """
    return msgpack.packb(data, default=_ext, use_bin_type=True)


QUANTUM = 65535
"""Steps of a mesh's bounding box per axis in the compact page (16-bit positions)."""


@dataclass(frozen=True)
class _SharedMesh:
    """A node's mesh in the compact page: a distinct geometry and its materials (keys)."""

    geometry: str
    materials: tuple[str, ...]


def encode_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[dict, bytes, bytes]:
    """The compact page's encoding of a triangle mesh (see the module docstring).

    Args:
        vertices: (V, 3) positions [m].
        faces: (F, 3) vertex indices.

    Returns:
        ``(header, positions, index)``: ``header`` has ``vertices`` (the count used by the
        faces), ``low`` (3,) and ``step`` (3,) [m] (a position is ``low + step * q``) and
        ``index_bits`` (16 or 32); ``positions`` the 3 V uint16 differences, x then y then
        z; ``index`` the 3 F differences of the renumbered indices (uint16 or uint32).
    """
    flat = np.asarray(faces, dtype=np.int64).reshape(-1)
    used, first = np.unique(flat, return_index=True)
    order = used[np.argsort(first)]  # old vertex numbers, in order of first use
    renumber = np.empty(int(flat.max(initial=-1)) + 1, dtype=np.int64)
    renumber[order] = np.arange(len(order))
    v = np.asarray(vertices, dtype=np.float64)[order]
    low = v.min(axis=0) if len(v) else np.zeros(3)
    step = (v.max(axis=0) - low) / QUANTUM if len(v) else np.zeros(3)
    q = np.zeros(v.shape, dtype=np.int64)
    nz = step > 0
    q[:, nz] = np.round((v[:, nz] - low[nz]) / step[nz]).astype(np.int64)
    dq = np.diff(q, axis=0, prepend=0) % 2**16
    index = renumber[flat]
    bits = 16 if len(v) <= 2**16 else 32
    di = np.diff(index, prepend=0) % 2**bits
    header = {"vertices": len(v), "low": low.tolist(), "step": step.tolist(), "index_bits": bits}
    return (header, dq.astype(np.uint16).tobytes("F"),
            di.astype(np.uint16 if bits == 16 else np.uint32).tobytes())


def decode_mesh(header: dict, positions: bytes, index: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The ``(vertices (V, 3) [m], faces (F, 3))`` of :func:`encode_mesh`, as the page decodes."""
    n = header["vertices"]
    q = np.cumsum(np.frombuffer(positions, dtype=np.uint16).reshape(3, n).T.astype(np.int64),
                  axis=0) % 2**16
    vertices = np.asarray(header["low"]) + np.asarray(header["step"]) * q
    bits = header["index_bits"]
    d = np.frombuffer(index, dtype=np.uint16 if bits == 16 else np.uint32).astype(np.int64)
    return vertices.astype(np.float32), (np.cumsum(d) % 2**bits).reshape(-1, 3)


def _material_json(material) -> dict:
    """A three.js material's JSON (``MaterialLoader``'s input) from a meshcat material."""
    data = material.lower({})
    data = {k: v for k, v in data.items() if k != "uuid"}
    return data


class PageWindow:
    """A ``meshcat.Visualizer`` window that keeps the scene here and writes its static page.

    Use it as ``meshcat.Visualizer(window=PageWindow())``; ``vis.static_html()`` then gives
    the compact page (``compact=True``) or the page meshcat's server would give for the same
    commands (``compact=False``).

    Args:
        compact: write the compact page (each mesh once, compressed, with the overlay).
    """

    def __init__(self, compact: bool = True):
        self.tree = SceneTree()
        self.compact = compact
        self.overlay: dict | None = None
        """The overlay's data (:func:`multiarm_pin.app.replay_overlay.overlay_data`)."""
        self.title = "MeshCat"
        self._geometries: dict[str, tuple[np.ndarray, np.ndarray, tuple]] = {}
        self._materials: dict[str, dict] = {}

    def _shared(self, command) -> _SharedMesh | None:
        """The node record of a ``set_object`` of a :class:`CompactMesh` mesh, else None."""
        obj = getattr(command, "object", None)
        if not (self.compact and isinstance(command, SetObject)
                and isinstance(getattr(obj, "geometry", None), CompactMesh)):
            return None
        geom = obj.geometry
        vertices = np.ascontiguousarray(geom.vertices, dtype=np.float32)
        faces = np.ascontiguousarray(geom.faces, dtype=np.uint32)
        groups = tuple(geom.groups) if len(geom.groups) > 1 else ((0, len(faces)),)
        h = hashlib.sha256(vertices.tobytes())
        h.update(faces.tobytes())
        h.update(repr(groups).encode())
        key = h.hexdigest()
        self._geometries.setdefault(key, (vertices, faces, groups))
        materials = getattr(obj, "materials", None) or [obj.material]
        keys = []
        for m in materials:
            data = _material_json(m)
            mkey = json.dumps(data, sort_keys=True)
            self._materials.setdefault(mkey, data)
            keys.append(mkey)
        return _SharedMesh(key, tuple(keys))

    def send(self, command) -> None:
        """Keep one scene command (``meshcat.commands``), as the server's ``handle_zmq`` does."""
        lowered = None
        shared = self._shared(command)
        if shared is None:
            lowered = command.lower()
            cmd = lowered["type"]
        else:
            cmd = "set_object"
        if cmd not in MESHCAT_COMMANDS:
            raise ValueError(f"PageWindow: unsupported Meshcat command {cmd!r}")
        path_str = lowered["path"] if shared is None else command.path.lower()
        path = [p for p in path_str.split("/") if p]
        if cmd == "set_object":
            node = find_node(self.tree, path)
            node.object = shared if shared is not None else pack(lowered)
            node.properties = []
        elif cmd == "set_transform":
            find_node(self.tree, path).transform = pack(lowered)
        elif cmd == "set_property":
            find_node(self.tree, path).properties.append(pack(lowered))
        elif cmd == "set_animation":
            find_node(self.tree, path).animation = pack(lowered)
        elif path:  # delete
            parent = find_node(self.tree, path[:-1])
            if path[-1] in parent:
                del parent[path[-1]]
        else:
            self.tree = SceneTree()

    def _commands(self):
        """``(path, packed command or _SharedMesh)`` of the scene, in the server's order."""
        stack = [((), self.tree)]
        while stack:
            path, node = stack.pop()
            if node.object is not None:
                yield path, node.object
            for p in node.properties:
                yield path, p
            if node.transform is not None:
                yield path, node.transform
            if node.animation is not None:
                yield path, node.animation
            stack.extend(reversed([(path + (k,), v) for k, v in node.items()]))

    def get_scene(self) -> str:
        """The self-contained HTML page of the scene (what ``Visualizer.static_html`` returns)."""
        with open(os.path.join(VIEWER_ROOT, "main.min.js")) as f:
            mainminjs = "".join(f.readlines())
        if not self.compact:
            parts = []
            for node in walk(self.tree):
                if node.object is not None:
                    parts.append(create_command(node.object))
                parts.extend(create_command(p) for p in node.properties)
                if node.transform is not None:
                    parts.append(create_command(node.transform))
                if node.animation is not None:
                    parts.append(create_command(node.animation))
            return _PAGE.format(mainminjs=mainminjs, commands="".join(parts))
        return self._compact_page(mainminjs)

    def _compact_page(self, mainminjs: str) -> str:
        block = bytearray()

        def put(data: bytes) -> list[int]:
            start = len(block)
            block.extend(data)
            return [start, len(data)]

        meshes, materials, nodes, commands = [], [], [], []
        mesh_ids: dict[str, int] = {}
        material_ids: dict[str, int] = {}
        for path, item in self._commands():
            if not isinstance(item, _SharedMesh):
                commands.append(put(item))
                continue
            if item.geometry not in mesh_ids:
                vertices, faces, groups = self._geometries[item.geometry]
                header, positions, index = encode_mesh(vertices, faces)
                header.update(positions=put(positions), index=put(index),
                              groups=[list(g) for g in groups])
                mesh_ids[item.geometry] = len(meshes)
                meshes.append(header)
            for m in item.materials:
                if m not in material_ids:
                    material_ids[m] = len(materials)
                    materials.append(self._materials[m])
            nodes.append(["/" + "/".join(path), mesh_ids[item.geometry],
                          [material_ids[m] for m in item.materials]])
        manifest = {"meshes": meshes, "materials": materials, "nodes": nodes,
                    "commands": commands, "overlay": self.overlay}
        text = json.dumps(manifest, separators=(",", ":"), allow_nan=False)
        packed = base64.b64encode(zlib.compress(bytes(block), 9)).decode("ascii")
        return _COMPACT_PAGE.format(
            title=_html_text(self.title), mainminjs=mainminjs,
            manifest=text.replace("<", "\\u003c"), block=packed, loader_js=_LOADER_JS,
            **(_OVERLAY_PARTS if self.overlay is not None else dict.fromkeys(_OVERLAY_PARTS, "")))


_OVERLAY_PARTS = {"overlay_css": replay_overlay.OVERLAY_CSS,
                  "overlay_html": replay_overlay.OVERLAY_HTML,
                  "overlay_js": replay_overlay.OVERLAY_JS}


def _html_text(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def decode_block(html: str) -> tuple[dict, bytes]:
    """``(manifest, inflated block)`` of a compact page (what its loader script reads).

    Raises:
        ValueError: not a compact replay page.
    """
    m = re.search(r'<script id="multiarm-manifest" type="application/json">(.*?)</script>',
                  html, re.S)
    b = re.search(r'<script id="multiarm-block" type="application/octet-stream">(.*?)</script>',
                  html, re.S)
    if m is None or b is None:
        raise ValueError("not a compact replay page (no manifest or data block)")
    return json.loads(m.group(1)), zlib.decompress(
        base64.b64decode(b.group(1)))


def page_visualizer(compact: bool = True) -> meshcat.Visualizer:
    """A ``meshcat.Visualizer`` on a :class:`PageWindow` (no server, nothing printed)."""
    return meshcat.Visualizer(window=PageWindow(compact=compact))


__all__ = ["PageWindow", "QUANTUM", "decode_block", "decode_mesh", "encode_mesh",
           "page_visualizer", "pack"]
