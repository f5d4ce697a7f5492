"""The HTML report's 3D scene as a user sees it: drawn by headless chromium through WebGL2
(SwiftShader), read back pixel by pixel; its JSON survives any name; its frames thinned
without losing a finding."""

from __future__ import annotations

import html
import json
import re
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_report_html import chromium

from verne_post.machine import load_machine
from verne_post.options import PostOptions
from verne_post.pipeline import postprocess
from verne_post.report.html import render, write_html_report
from verne_post.report.scene3d import MAX_FRAMES, SCENE_SCRIPT, SCENE_STYLE, example_scene, normalise

EXAMPLES = Path(__file__).parent.parent / "examples"
WEBGL = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader")
NO_WEBGL = ("--disable-gpu", "--disable-software-rasterizer")


@pytest.fixture(scope="module")
def posted() -> tuple[Any, PostOptions, Any]:
    machine, options = load_machine(None), PostOptions(plan=False)
    return machine, options, postprocess(str(EXAMPLES / "nx_swarf_inch_crlf.cls"), machine, options)


def browse(url: str, profile: Path, flags: tuple[str, ...] = WEBGL) -> str:
    """The DOM after the page's scripts ran, in chromium headless, offline."""
    done = subprocess.run(
        [chromium(), "--headless", "--no-sandbox", *flags, "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--proxy-server=127.0.0.1:9",
         f"--user-data-dir={profile}", "--window-size=1280,2600", "--virtual-time-budget=5000", "--dump-dom", url],
        capture_output=True, text=True, timeout=120, check=False)
    return done.stdout


def element(dom: str, name: str) -> str:
    found = re.search(rf'id="{name}"[^>]*>([^<]*)<', dom)
    assert found, f"no #{name} in the page"
    return html.unescape(found.group(1))


def probe(page: Path, profile: Path, fragment: str) -> tuple[dict, str]:
    dom = browse(f"{page.as_uri()}#{fragment}", profile)
    assert 'id="script-error"' not in dom
    assert element(dom, "scene-error") == ""
    assert element(dom, "scene-drawn") == "1"
    return json.loads(element(dom, "scene-probe")), dom


def direction(hex_colour: str) -> np.ndarray:
    v = np.array([int(hex_colour[k:k + 2], 16) for k in (1, 3, 5)], dtype=float)
    return v / np.linalg.norm(v)


def group_of(rgba: list[int] | None, colours: dict[str, str]) -> str | None:
    """The group whose colour a lit pixel is (shading scales a colour: its direction is kept)."""
    if rgba is None or max(rgba[:3]) < 10:
        return None
    v = np.asarray(rgba[:3], dtype=float)
    v /= np.linalg.norm(v)
    scores = {g: float(v @ direction(c)) for g, c in colours.items()}
    best = max(scores, key=scores.get)
    return best if scores[best] > 0.995 else None


def test_scene_is_drawn_and_its_head_moves(tmp_path: Path, posted: tuple) -> None:
    scene = example_scene()
    page = tmp_path / "scene.html"
    write_html_report(page, *posted, scene=scene)
    text = page.read_text(encoding="ascii")
    assert text.count(SCENE_SCRIPT.strip()[:60]) == 1 and "Machine and setup in 3D" in text
    # The finding links to its CL line, shown in the excerpts, and its button to its frame.
    finding = scene["findings"][0]
    assert f'<a href="#cl-{finding["line"]}">CL line {finding["line"]}</a>' in text
    assert f'id="cl-{finding["line"]}"' in text and f'data-frame="{finding["frame"]}"' in text
    colours = normalise(scene)["colours"]
    last = len(scene["frames"]["t"]) - 1

    first, _ = probe(page, tmp_path / "p", "frame=0&probe")
    assert first["frame"] == 0 and first["width"] > 500
    assert first["nonBackground"] > 0.1 * first["width"] * first["height"]
    at = {b["name"]: b for b in first["bodies"]}
    assert group_of(at["stock"]["rgba"], colours) == "stock"
    assert group_of(at["clamp 1"]["rgba"], colours) == "fixture"
    spindle = at["spindle"]
    assert group_of(spindle["rgba"], colours) == "head"

    end, dom = probe(page, tmp_path / "p", f"frame={last}&probe={spindle['x']},{spindle['y']}")
    assert end["frame"] == last
    assert element(dom, "scene-frame-label") == f"frame {last} of {last}: t 9.800 s, CL line {100 + 2 * last}"
    moved = {b["name"]: b for b in end["bodies"]}["spindle"]
    assert np.hypot(moved["x"] - spindle["x"], moved["y"] - spindle["y"]) > 30
    assert group_of(moved["rgba"], colours) == "head"
    # Where the spindle was at frame 0 something else (or nothing) is drawn now.
    assert group_of(end["points"][0]["rgba"], colours) not in ("head", "holder", "tool")
    assert end["nonBackground"] != first["nonBackground"]
    # The stock stays where it was.
    assert {b["name"]: b for b in end["bodies"]}["stock"]["x"] == at["stock"]["x"]


def test_no_webgl2_says_so(tmp_path: Path, posted: tuple) -> None:
    page = tmp_path / "scene.html"
    page.write_text(render(*posted, scene=example_scene()), encoding="ascii")
    dom = browse(page.as_uri(), tmp_path / "p", NO_WEBGL)
    assert "no WebGL2" in element(dom, "scene-error")
    assert element(dom, "scene-drawn") == ""
    assert re.search(r'id="scene-message"[^>]*style="display: block;"[^>]*>The 3D view could not be drawn', dom)
    assert re.search(r'id="plots-drawn"[^>]*>9<', dom)  # the rest of the report is drawn all the same


def test_names_cannot_break_the_page(tmp_path: Path, posted: tuple) -> None:
    evil = '</script><script>document.title="broken"</script><!-- & "quoted"'
    scene = example_scene(12)
    scene["fixed"][1]["name"] = evil
    scene["fixed"][2]["group"] = evil
    scene["findings"] = [{"severity": "collision", "bodies": [evil, "holder"], "clearance": -0.5, "line": 120,
                          "xyz": [0, 0, 0], "frame": 3}]
    # Every kind of body besides the example's: drawn without an error.
    scene["fixed"] += [
        {"name": "plate", "group": "fixture", "kind": "obox", "center": [0, -100, -50], "half": [60, 20, 10],
         "rotation": [0.866, -0.5, 0, 0.5, 0.866, 0, 0, 0, 1]},
        {"name": "rod", "group": "machine", "kind": "capsule", "p0": [-200, 0, -60], "p1": [-200, 0, 100],
         "radius": 15},
        {"name": "bar", "group": "machine", "kind": "cylinder", "p0": [200, -50, -60], "p1": [200, 50, 0],
         "radius": 10}]
    scene["moving"].append({"name": "probe", "group": "probe", "kind": "mesh",
                            "triangles": [0, 0, 0, 30, 0, 0, 0, 30, 0, 0, 0, 0, 0, 30, 0, 0, 0, 30]})
    scene["frames"]["poses"] = [[*pose, 150, 0, 50, 1, 0, 0, 0, 1, 0, 0, 0, 1] for pose in scene["frames"]["poses"]]
    text = render(*posted, scene=scene)
    payload = re.search(r'<script type="application/json" id="scene-data">(.*?)</script>', text, re.S).group(1)
    assert json.loads(payload) == json.loads(json.dumps(normalise(scene)))
    assert json.loads(payload)["fixed"][1]["name"] == evil
    page = tmp_path / "evil.html"
    page.write_text(text, encoding="ascii")
    found, dom = probe(page, tmp_path / "p", "probe")
    assert "broken" not in re.search(r"<title>(.*?)</title>", dom).group(1)
    assert found["bodies"][1]["name"] == evil
    assert {b["name"] for b in found["bodies"]} >= {"plate", "rod", "bar", "probe"}
    assert found["nonBackground"] > 0.1 * found["width"] * found["height"]
    listed = html.unescape(re.search(r'<ul id="scene-findings">(.*?)</ul>', dom, re.S).group(1))
    assert evil in re.sub(r"<button.*?</button>|<a .*?</a>", "", listed)


def test_without_a_scene_only_a_sentence(posted: tuple) -> None:
    text = render(*posted)
    assert "Machine and setup in 3D" in text and "No 3D scene was given" in text
    assert "scene-canvas" not in text and "scene-data" not in text
    assert SCENE_STYLE.strip()[:40] not in text and "sceneSetFrame" not in text


def test_frames_are_thinned_keeping_the_findings() -> None:
    scene = example_scene(MAX_FRAMES * 2 + 7)
    frames = len(scene["frames"]["t"])
    scene["findings"].append({"severity": "collision", "bodies": ["a", "b"], "clearance": 0, "line": 1,
                              "xyz": [1, 2, 3], "frame": 2001})
    data = normalise(scene)
    kept = data["frames"]["t"]
    assert MAX_FRAMES <= len(kept) <= MAX_FRAMES + 2 and len(data["frames"]["poses"]) == len(kept)
    for f in data["findings"]:  # a finding's frame shows its own time
        assert kept[f["frame"]] == round(0.2 * (2001 if f["line"] == 1 else frames - 1), 3)
    assert data["findings"][0]["severity"] == "collision"  # the collision listed first
    assert max(data["path"]["frame"]) == len(kept) - 1 and data["path"]["frame"] == sorted(data["path"]["frame"])
    assert all(len(str(v)) <= 12 for v in data["frames"]["poses"][5])  # 3 decimals


def test_a_wrong_scene_is_refused() -> None:
    scene = example_scene(5)
    scene["frames"]["poses"][2] = scene["frames"]["poses"][2][:-1]
    with pytest.raises(ValueError, match="pose numbers a frame"):
        normalise(scene)
    scene = example_scene(5)
    scene["fixed"][0]["kind"] = "torus"
    with pytest.raises(ValueError, match="torus"):
        normalise(scene)
    scene = example_scene(5)
    scene["findings"][0]["frame"] = 5
    with pytest.raises(ValueError, match="frame 5 outside"):
        normalise(scene)


def test_a_posted_program_shows_its_own_bodies_where_the_kinematics_puts_them(tmp_path: Path) -> None:
    """'post --report x.html' draws the program's own scene: the setup where it was given, the
    cutter at the tip and along the axis the forward kinematics gives for each frame's block
    end."""
    from click.testing import CliRunner

    import verne_post as vp
    from verne_post.cli import main
    from verne_post.report.post_scene import post_scene

    machine = load_machine(None)
    source = EXAMPLES / "nx_swarf_inch_crlf.cls"
    options = PostOptions(plan=False, stock=("box:-0.5,-0.5,-1.5,4.5,4.5,-0.9",))
    result = postprocess(str(source), machine, options)
    scene = post_scene(machine, result)
    assert scene is not None and not result.violations
    stock = next(b for b in scene["fixed"] if b["group"] == "stock")
    offset = np.asarray(machine.work_offset)
    assert np.allclose(stock["lo"], np.array([-0.5, -0.5, -1.5]) * 25.4 + offset)  # inch, part frame -> table
    names = [b["name"] for b in scene["moving"]]
    cutter = names.index("cutter")
    poses = np.asarray(scene["frames"]["poses"])
    pick = np.linspace(0, len(poses) - 1, 40).astype(int)
    chosen = [int(np.argmin(np.abs(np.cumsum(np.nan_to_num(result.duration)) - t)))
              for t in np.asarray(scene["frames"]["t"])[pick]]
    fk = vp.forward_kinematics(machine, result.blocks.joints[chosen],
                               tool_length=result.poses.tool_length[result.blocks.pose[chosen]])
    p0, p1 = poses[pick, 6 * cutter:6 * cutter + 3], poses[pick, 6 * cutter + 3:6 * cutter + 6]
    moved = np.linalg.norm(np.diff(result.blocks.tip, axis=0), axis=1)
    if np.all(moved > 0):  # frames found by time: where two blocks end at once the time names either
        assert np.allclose(p0, fk.tip, atol=1e-6)
    span = (p1 - p0) / np.linalg.norm(p1 - p0, axis=1, keepdims=True)
    assert np.allclose(span, fk.axis, atol=1e-6)

    page = tmp_path / "posted.html"
    code = CliRunner().invoke(main, ["post", str(source), "-o", str(tmp_path / "p.nc"), "--no-timing", "-q",
                                     "--stock", "box:-0.5,-0.5,-1.5,4.5,4.5,-0.9", "--report", str(page)])
    assert code.exit_code == 0, code.output
    text = page.read_text(encoding="ascii")
    assert "Machine and setup in 3D" in text
    first, _ = probe(page, tmp_path / "p", "frame=0&probe")
    assert first["nonBackground"] > 0.05 * first["width"] * first["height"]
    at = {b["name"]: b for b in first["bodies"]}
    colours = normalise(scene)["colours"]
    assert group_of(at["stock"]["rgba"], colours) == "stock"
