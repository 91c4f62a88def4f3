"""The offline replay page built in this process: Meshcat's scene tree without its server.

meshcat 0.3.2 writes a static page (``Visualizer.static_html``) by asking its server, a
subprocess reached over ZMQ, for the scene. The server keeps a tree of nodes, one per path;
each node holds the last packed ``set_object`` (which clears the node's properties), its
``set_property`` packets in order, the last ``set_transform`` and the last ``set_animation``.
It writes them node by node, in the tree's order, as base64 ``fetch`` commands into a page
that inlines the viewer's ``main.min.js`` (``handle_zmq`` in ``meshcat/servers/zmqserver.py``).

:class:`PageWindow` is a window for ``meshcat.Visualizer`` that keeps the same tree here and
writes the same page, so writing ``replay.html`` starts no server process and makes no ZMQ
round trip per command. Commands are packed by ``msgpack``'s C packer into the bytes of
meshcat's own pure-Python ``umsgpack.packb`` (same types, same encodings; the tests compare
the two packers and the two pages byte for byte).
"""

from __future__ import annotations

import os

import meshcat
import msgpack
import umsgpack
from meshcat.servers.tree import SceneTree, find_node, walk
from meshcat.servers.zmqserver import MESHCAT_COMMANDS, VIEWER_ROOT, create_command

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


class PageWindow:
    """A ``meshcat.Visualizer`` window that keeps the scene here and writes its static page.

    Use it as ``meshcat.Visualizer(window=PageWindow())``; ``vis.static_html()`` then gives
    the page meshcat's server would give for the same commands.
    """

    def __init__(self):
        self.tree = SceneTree()

    def send(self, command) -> None:
        """Keep one scene command (``meshcat.commands``), as the server's ``handle_zmq`` does."""
        lowered = command.lower()
        cmd = lowered["type"]
        if cmd not in MESHCAT_COMMANDS:
            raise ValueError(f"PageWindow: unsupported Meshcat command {cmd!r}")
        path = [p for p in lowered["path"].split("/") if p]
        data = pack(lowered)
        if cmd == "set_transform":
            find_node(self.tree, path).transform = data
        elif cmd == "set_object":
            node = find_node(self.tree, path)
            node.object = data
            node.properties = []
        elif cmd == "set_property":
            find_node(self.tree, path).properties.append(data)
        elif cmd == "set_animation":
            find_node(self.tree, path).animation = data
        elif path:  # delete
            parent = find_node(self.tree, path[:-1])
            if path[-1] in parent:
                del parent[path[-1]]
        else:
            self.tree = SceneTree()

    def get_scene(self) -> str:
        """The self-contained HTML page of the scene (what ``Visualizer.static_html`` returns)."""
        parts = []
        for node in walk(self.tree):
            if node.object is not None:
                parts.append(create_command(node.object))
            parts.extend(create_command(p) for p in node.properties)
            if node.transform is not None:
                parts.append(create_command(node.transform))
            if node.animation is not None:
                parts.append(create_command(node.animation))
        with open(os.path.join(VIEWER_ROOT, "main.min.js")) as f:
            mainminjs = "".join(f.readlines())
        return _PAGE.format(mainminjs=mainminjs, commands="".join(parts))


def page_visualizer() -> meshcat.Visualizer:
    """A ``meshcat.Visualizer`` on a :class:`PageWindow` (no server, nothing printed)."""
    return meshcat.Visualizer(window=PageWindow())


__all__ = ["PageWindow", "page_visualizer", "pack"]
