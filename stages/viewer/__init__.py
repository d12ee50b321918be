"""``livescene view``: a live viewer of a trained run in the browser (viser, the library nerfstudio's viewer uses).

The training cameras are drawn as frustums, each object has a state slider, language commands move the
sliders, a relevancy query shows its map instead of colour, and the client's camera is rendered in a
background thread: a preview while the view keeps changing, the full resolution once it is still.

viser is an optional dependency (``pip install -e ".[viewer]"``); only ``server`` imports it (through
``viser_dependency``, whose error gives the pip command), so the camera, resolution, render-loop and
language modules are importable, and tested, without it.
"""
