"""The scene page in a real browser: no console errors, every image loads, the sliders scrub."""

from __future__ import annotations

import json
from pathlib import Path

from report_browser import ARTIFACTS, make_fake_results

from stages.report.cli import main as report_main

PLAN = {"capture": {"needed": True, "why": "synthetic spec"}, "frames": {"needed": True, "why": "video"},
        "poses": {"needed": True, "why": "COLMAP"}, "states": {"needed": True, "why": "key frames given"},
        "labels": {"needed": False, "why": "scene has no masks"},
        "train[livescene]": {"needed": True, "why": "listed"}, "train[conerf]": {"needed": True, "why": "listed"},
        "sweep[livescene]": {"needed": True, "why": "sliders"}, "control[livescene]": {"needed": True, "why": "x"},
        "stability": {"needed": False, "why": "stability.run is false"}}


def build_page(tmp_path: Path, data: Path, plan: dict = PLAN) -> Path:
    results = make_fake_results(tmp_path, data)
    page = tmp_path / "reports" / "scenes" / "fake.html"
    code = report_main(["scene", "--scene", "fake", "--results", str(results), "--data", str(data),
                        "--methods", "livescene,conerf", "--plan-json", json.dumps(plan), "--out", str(page),
                        "--summary", str(tmp_path / "summary.json")])
    assert code == 0
    return page


def test_page_in_chromium(tmp_path, tiny_dataset, chromium):
    page = build_page(tmp_path, tiny_dataset.root)
    chromium.load(page.as_uri())
    images = chromium.evaluate("Array.from(document.images).map(i => [i.alt, i.complete && i.naturalWidth > 0])")
    # truth + 2 x (render + error) per test view, relevancy maps, 3 sliders, 1 command render
    assert len(images) >= 3 * 5 + 3
    assert [alt for alt, ok in images if not ok] == []
    slider = """(async () => {
      const el = document.querySelector('input.sweep');
      const img = document.getElementById(el.dataset.target);
      const before = [img.src, document.getElementById(el.dataset.target + '-value').textContent];
      el.value = el.max; el.dispatchEvent(new Event('input'));
      await img.decode();
      const after = [img.src, document.getElementById(el.dataset.target + '-value').textContent];
      return {before, after, loaded: img.complete && img.naturalWidth > 0,
              count: document.querySelectorAll('input.sweep').length};
    })()"""
    moved = chromium.evaluate(slider, await_promise=True)
    assert moved["count"] == 3
    assert moved["before"][0] != moved["after"][0], "moving the slider did not change the image"
    assert (moved["before"][1], moved["after"][1]) == ("0.00", "1.00")
    assert moved["loaded"]
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    chromium.screenshot(ARTIFACTS / "scene_page.png")
    assert (ARTIFACTS / "scene_page.png").stat().st_size > 10_000
    assert chromium.errors() == []


def test_page_is_self_contained_and_says_why(tmp_path, tiny_dataset):
    html = build_page(tmp_path, tiny_dataset.root).read_text()
    for section in ("rules", "timings", "poses", "states", "methods", "curves", "grid", "sliders", "relevancy",
                    "unseen", "locality", "commands", "stability"):
        assert f'<section id="{section}">' in html
    locality = html.split('<section id="locality">')[1].split("</section>")[0]
    assert locality.count(">local<") == 3 and locality.count(">not local<") == 3  # 3 objects x 2 methods
    assert "http://" not in html.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "https://" not in html
    assert "<svg" in html and "eval PSNR (dB)" in html  # the error-vs-run-time plot is inline SVG
    assert "not available: torchvision is not installed" in html  # LPIPS says why
    assert "stability.run is false" in html  # absent stability summary: the page says why
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["methods"]["conerf"]["psnr"] == 21.0


def test_page_without_evaluations(tmp_path, tiny_dataset):
    """A scene whose trainings have not run still gets a page that says so, section by section."""
    data = tiny_dataset.root
    page = tmp_path / "empty.html"
    plan = {"train[livescene]": {"needed": False, "why": "method not listed for this scene"},
            "sweep[livescene]": {"needed": False, "why": "not in report.sweep_methods"}}
    assert report_main(["scene", "--scene", "empty", "--results", str(tmp_path / "nothing"), "--data", str(data),
                        "--methods", "livescene", "--plan-json", json.dumps(plan), "--out", str(page)]) == 0
    html = page.read_text()
    assert "not in report.sweep_methods" in html
    assert "No periodic evaluation" in html
    assert "No benchmark files" in html


def test_bad_plan_json_is_an_input_error(tmp_path, capsys):
    code = report_main(["scene", "--scene", "x", "--results", str(tmp_path), "--plan-json", "{nope",
                        "--out", str(tmp_path / "x.html")])
    assert code == 2
    assert "--plan-json" in capsys.readouterr().err
