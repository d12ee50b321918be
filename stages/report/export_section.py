"""The scene page's "Export" section: per exported state, the files' sizes and counts, timings and a thumbnail.

Reads the ``export.json`` of each method's export folder (``livescene export``; its fields are described in
docs/export.md) and the thumbnails it names. The section is given the folders; it does not look for them.
"""

from __future__ import annotations

from html import escape
from pathlib import Path
from typing import Any

from stages.scene.dataset import file_stem

from .html_parts import fmt, missing, table
from .images import file_data_uri
from .scene_data import read_json


def _mib(n_bytes: Any) -> str:
    return fmt(n_bytes / 2**20, 2, " MiB") if isinstance(n_bytes, int | float) else "–"


def _count(entry: dict[str, Any] | None) -> str:
    """'87,655 v / 159,110 t' for a mesh, '114,309 pts' for points, '–' when absent."""
    if not entry:
        return "–"
    if "triangles" in entry:
        return f"{entry.get('vertices', 0):,} v / {entry['triangles']:,} t"
    return f"{entry.get('points', 0):,} pts"


def _states(states: dict[str, float]) -> str:
    return escape(", ".join(f"{name}={value:g}" for name, value in states.items()) or "no objects")


def _one_method(method: str, folder: Path) -> str:
    record = read_json(folder / "export.json")
    if record is None:
        return missing(f"{method}: {folder}/export.json is missing (the export did not finish).")
    objects = [str(o) for o in record.get("objects", [])]
    with_parts = bool((record.get("options") or {}).get("objects"))
    headers = ["states", "scene mesh", "size", "scene points", "size"]
    headers += [f"{o} part" for o in objects] if with_parts else []
    headers += ["render s", "fuse s", "extract s", "write s", "total s"]
    rows, thumbs = [], []
    for ex in record.get("exports", []):
        files, t = ex.get("files") or {}, ex.get("timings_s") or {}
        mesh, points = files.get("scene_mesh"), files.get("scene_points")
        row = [_states(ex.get("states") or {}), _count(mesh), _mib((mesh or {}).get("bytes")), _count(points),
               _mib((points or {}).get("bytes"))]
        if with_parts:
            row += [_count(files.get(f"objects/{file_stem(o)}_mesh")) for o in objects]  # the exporter's names
        row += [t.get("render"), t.get("fuse"), t.get("extract"), t.get("write"), t.get("total")]
        rows.append(row)
        uri = file_data_uri(folder / ex["thumbnail"]) if ex.get("thumbnail") else None
        if uri:
            thumbs.append(f'<figure><img src="{uri}" alt="export at {_states(ex.get("states") or {})}">'
                          f"<figcaption>{_states(ex.get('states') or {})}</figcaption></figure>")
    opts = record.get("options") or {}
    size = record.get("render_size") or ["?", "?"]
    load = record.get("loadavg")
    head = (f"<p><b>{escape(method)}</b> at step {record.get('step', '?')}: {record.get('views', '?')} training "
            f"views rendered at {size[0]}x{size[1]} per state and fused (TSDF, voxel "
            f"{fmt(record.get('voxel'), 4)} scene units), {escape(str(opts.get('fmt', '?')))} files in "
            f"<code>{escape(str(folder))}</code>; {fmt(record.get('total_seconds'), 1)} s in all"
            + (f" at load {fmt(load[0], 2)}" if isinstance(load, list) and load else "") + ".</p>")
    return head + table(headers, rows) + (f"<div>{''.join(thumbs)}</div>" if thumbs else "")


def section_export(folders: dict[str, Path], skipped: str = "no method of this scene is in export.methods") -> str:
    """HTML of the section for ``folders`` (method -> its export folder); ``skipped`` says why there is none."""
    if not folders:
        return missing(skipped)
    intro = ("<p>The room as a mesh and a coloured point cloud at each exported state combination, with each "
             "object's part alone when the scene has masks (docs/export.md). Geometry comes from rendered depth, "
             "so it is only as good as the run: a run flagged above as undertrained gives a rough mesh.</p>")
    return intro + "".join(_one_method(m, Path(f)) for m, f in folders.items())
