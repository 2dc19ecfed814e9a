"""The main job and its report: `stressbots run`, `stressbots simulate` in closed loop, report.html.

Runs use the example scenario without noise (`--noise none`), where the closed loop assembles the tee
deterministically, plus a run that does not assemble (a tiny time budget): a failed run must still
give the full report with its reason and event log, and exit status 0. A controller that raises is an
internal error (exit 1), not a failed run.
"""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from stressbots.report import SECTIONS, animation_data, outcome_text

from .conftest import EXAMPLES, assert_user_error

EXAMPLE = EXAMPLES / "four-robots.toml"
SECTION_IDS = [sid for sid, _ in SECTIONS]


class _Refs(HTMLParser):
    """Every URL-bearing attribute, the ids and the script/style tags of a page."""

    def __init__(self):
        super().__init__()
        self.urls: list[tuple[str, str, str]] = []
        self.ids: list[str] = []
        self.tags: list[tuple[str, dict]] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        if "id" in a:
            self.ids.append(a["id"])
        for key in ("src", "href", "action", "poster", "data", "srcset"):
            if a.get(key) is not None:
                self.urls.append((tag, key, a[key]))


def check_self_contained(text: str) -> _Refs:
    """No external resource: every src/href is a data: URI, a fragment or a relative file name."""
    p = _Refs()
    p.feed(text)
    for tag, key, url in p.urls:
        low = url.strip().lower()
        assert not low.startswith(("http:", "https:", "//", "ftp:", "file:")), (tag, key, url)
        if tag in ("img", "script", "link") and key in ("src", "href"):
            assert low.startswith("data:"), (tag, key, url)  # embedded, not a file beside it
    assert not re.search(r"url\(\s*['\"]?\s*(https?:)?//", text, re.I)
    assert "@import" not in text
    for tag, a in p.tags:
        if tag == "script":
            assert "src" not in a, a
    return p


def _result(out):
    return json.loads((out / "result.json").read_text())


# ----------------------------------------------------------------------------------------------------
# stressbots run


@pytest.mark.xdist_group("main_job")
def test_run_assembles_without_noise_and_writes_the_report(main_job):
    r, out = main_job  # `stressbots run EXAMPLE --noise none --seed 3`, shared with the other main-job tests
    assert r.code == 0, r.err
    assert "assembled" in r.out and "not assembled" not in r.out and "report.html" in r.out
    assert "B, D, A, C" in r.out  # the analysis summary
    res = _result(out)
    assert res["success"] is True and res["seed"] == 3 and res["mode"] == "closed-loop" and res["failure"] is None
    assert [x["name"] for x in res["robots"]] == ["A", "B", "C", "D"]
    for x in res["robots"]:  # SPEC 7 keys
        assert set(x) >= {"name", "final", "goal", "docked", "position_error_um", "heading_error_deg"}
        assert x["docked"] and len(x["final"]) == 3 and len(x["goal"]) == 3
    assert res["provenance"]["seed"] == 3 and "numpy" in res["provenance"]["versions"]
    assert res["noise"]["speed_rel_sd"] == 0.0
    plan = json.loads((out / "plan.json").read_text())
    assert plan["format"] == "stressbots.plan/1" and plan["robots"] == ["A", "B", "C", "D"] and plan["steps"]
    assert json.loads((out / "states.json").read_text())["count"] == 5
    wave = np.load(out / "waveform.npy")
    assert wave.ndim == 2 and wave.shape[1] == 2 and wave.shape[0] > 1000
    assert wave[:, 1].min() >= 0.0 and wave[:, 1].max() <= 200.0
    segs = json.loads((out / "waveform.json").read_text())
    assert sum(1 for s in segs if s["kind"] == "drive") >= len(plan["steps"])
    for name in ("plan.png", "run.png", "structure.png", "waveform.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    html = (out / "report.html").read_text(encoding="utf-8")
    assert len(html.encode()) < 10_000_000
    refs = check_self_contained(html)
    for sid in SECTION_IDS:
        assert sid in refs.ids, sid
    assert "Assembled" in html and "run-animation-data" in html
    assert html.count("data:image/png;base64,") >= 4
    # the animation data is valid JSON with a few hundred frames of n robots
    m = re.search(r'<script type="application/json" id="run-animation-data">(.*?)</script>', html, re.S)
    assert m is not None
    data = json.loads(m.group(1).replace("<\\/", "</"))
    assert 100 <= len(data["t"]) <= 1000 and len(data["poses"][0]) == 3 * 4 and data["names"] == ["A", "B", "C", "D"]


@pytest.fixture(scope="module")
def cached_plan():
    """The example's nominal plan, computed once for the failure tests of this module."""
    from stressbots.control import nominal_plan
    from stressbots.scenario import load

    return nominal_plan(load(EXAMPLE))


def test_a_run_that_does_not_assemble_still_gets_the_full_report(run_cli, tmp_path, monkeypatch, cached_plan):
    import stressbots.control

    monkeypatch.setattr(stressbots.control, "nominal_plan", lambda _scenario, **_kw: cached_plan)
    out = tmp_path / "short"
    r = run_cli("run", EXAMPLE, "--out", out, "--noise", "none", "--time-budget-s", "20", "--quiet")
    assert r.code == 0, r.err  # the job ran; the run failed
    res = _result(out)
    assert res["success"] is False and res["failure"]
    assert r.out == "" and r.err == ""  # --quiet: nothing but errors
    html = (out / "report.html").read_text(encoding="utf-8")
    refs = check_self_contained(html)
    assert all(sid in refs.ids for sid in SECTION_IDS)
    assert 'class="banner fail"' in html and "Not assembled" in html
    from html import escape

    assert escape(outcome_text(res)[len("not assembled: "):]) in html  # the reason, prominently
    assert "outcome" in html and "stopped:" in html  # the event log ends with the reason
    for name in ("plan.json", "waveform.npy", "run.png", "structure.png"):
        assert (out / name).exists(), name


def test_a_controller_that_raises_is_an_internal_error(run_cli, tmp_path, monkeypatch, cached_plan):
    """An exception inside the computation is a bug: one `error: internal error:` line, exit 1, no
    traceback (unless STRESSBOTS_DEBUG is set), never a normal failed run with exit 0."""
    import stressbots.control

    def broken(scenario, plant, **kw):
        plant.observe()
        raise RuntimeError("controller exploded on purpose")

    monkeypatch.setattr(stressbots.control, "nominal_plan", lambda _scenario, **_kw: cached_plan)
    monkeypatch.setattr(stressbots.control, "assemble", broken)
    monkeypatch.delenv("STRESSBOTS_DEBUG", raising=False)
    for cmd in ("run", "simulate"):
        r = run_cli(cmd, EXAMPLE, "--out", tmp_path / cmd, "--noise", "none", "-q")
        assert r.code == 1, (cmd, r.code, r.err)
        lines = r.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: internal error: RuntimeError: controller exploded on purpose"), r.err
        assert "Traceback" not in r.err and r.out == ""
        assert not (tmp_path / cmd / "result.json").exists()  # no result pretends the run happened


def test_run_bad_input(run_cli, tmp_path):
    assert_user_error(run_cli("run", tmp_path / "missing.toml", "--out", tmp_path / "o"), "missing.toml")
    f = tmp_path / "file"
    f.write_text("x")
    assert_user_error(run_cli("run", EXAMPLE, "--out", f), "--out")
    assert_user_error(run_cli("run", EXAMPLE, "--out", EXAMPLE), "--out")
    assert_user_error(run_cli("run", EXAMPLE, "--out", tmp_path / "o", "--time-budget-s", "-1"), "--time-budget-s")
    assert_user_error(run_cli("run", EXAMPLE, "--out", tmp_path / "o", "--noise", "loud"), "loud")
    assert_user_error(run_cli("run", EXAMPLE), "--out")
    no_start = tmp_path / "nostart.toml"
    no_start.write_text(re.sub(r"^start = .*$", "", EXAMPLE.read_text(), count=1, flags=re.M))
    assert_user_error(run_cli("run", no_start, "--out", tmp_path / "o2"), "nostart.toml", "start")
    text = EXAMPLE.read_text()
    no_goal = tmp_path / "nogoal.toml"
    no_goal.write_text(text[: text.index("[structure]")] + text[text.index("[noise]"):])
    assert_user_error(run_cli("run", no_goal, "--out", tmp_path / "o3"), "nogoal.toml", "goal")
    assert_user_error(run_cli("simulate", no_goal, "--out", tmp_path / "o4"), "nogoal.toml", "goal")
    # an input file inside the output folder is never overwritten
    folder = tmp_path / "inplace"
    folder.mkdir()
    clash = folder / "result.json"
    clash.write_text(EXAMPLE.read_text())
    assert_user_error(run_cli("run", clash, "--out", folder), "result.json")
    assert clash.read_text() == EXAMPLE.read_text()


# ----------------------------------------------------------------------------------------------------
# stressbots simulate, closed loop


def test_simulate_without_a_plan_runs_the_closed_loop(run_cli, tmp_path):
    out = tmp_path / "sim"
    r = run_cli("simulate", EXAMPLE, "--seed", "4", "--noise", "none", "--out", out)
    assert r.code == 0, r.err
    res = _result(out)
    assert res["success"] is True and res["seed"] == 4 and res["mode"] == "closed-loop"
    assert all(x["docked"] for x in res["robots"])
    assert res["shape_error_rms_um"] < 10.0
    for name in ("trajectory.png", "structure.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = (out / "animation.html").read_text(encoding="utf-8")
    check_self_contained(page)
    assert "stressbots-anim" in page
    assert "assembled" in r.out
    assert_user_error(run_cli("simulate", EXAMPLE, "--seed", "-1", "--out", out), "--seed")
    assert_user_error(run_cli("simulate", EXAMPLE, "--out", EXAMPLE), "--out")


# ----------------------------------------------------------------------------------------------------
# report.py pieces


def test_outcome_text_does_not_repeat_itself():
    assert outcome_text({"success": True}) == "assembled"
    assert outcome_text({"success": False, "failure": "G_1 could not be synchronised"}) == "not assembled: G_1 could not be synchronised"
    assert outcome_text({"success": False, "failure": "not assembled within the time budget of 5 s"}) == (
        "not assembled: within the time budget of 5 s")
    assert outcome_text({"success": False, "failure": None}) == "not assembled: unknown reason"


def test_animation_data_resamples_uniformly_and_keeps_headings_continuous():
    from stressbots.scenario import load

    scn = load(EXAMPLE)
    t = np.array([0.0, 1.0, 1.0, 3.0])
    p = np.zeros((4, 4, 3))
    p[:, :, 0] = np.array([0.0, 10.0, 12.0, 32.0])[:, None]
    p[:, :, 2] = np.array([6.2, 6.25, 0.0, 0.05])[:, None]  # wraps through 2 pi
    d = animation_data(scn, t, p, None, [{"t_s": 2.0, "robot": "A", "kind": "dock", "detail": "x</script>"}], max_frames=7)
    assert d["t"] == pytest.approx(np.linspace(0, 3, 7).tolist())
    xs = [row[0] for row in d["poses"]]
    assert xs[2] == pytest.approx(12.0) and xs[-1] == pytest.approx(32.0)  # the repeated time keeps its last sample
    th = [row[2] for row in d["poses"]]
    assert max(abs(b - a) for a, b in zip(th[:-1], th[1:], strict=True)) < 0.1
    assert d["goals"] is None and d["events"][0]["t"] == 2.0
    from stressbots.report import animation_page

    page = animation_page(d, title="t <b>")
    assert "x</script>" not in page and "t &lt;b&gt;" in page
    check_self_contained(page)


@pytest.mark.xdist_group("main_job")
def test_animation_draws_planned_slots_and_retargeted_slots_only_from_g1(main_job):
    """The animation names the two kinds of slot apart: the planned slots (result.json `goal`) from the
    start, the re-targeted ones (`goal_after_G1`) only from the time G_1 formed (the controller's event)."""
    _, out = main_job
    res = _result(out)
    html = (out / "report.html").read_text(encoding="utf-8")
    m = re.search(r'<script type="application/json" id="run-animation-data">(.*?)</script>', html, re.S)
    assert m is not None
    data = json.loads(m.group(1).replace("<\\/", "</"))
    planned = np.array([x["goal"] for x in res["robots"]], dtype=float)
    got = np.array(data["goals"], dtype=float)
    assert np.allclose(got[:, :2], planned[:, :2], atol=1e-3)
    assert np.allclose(np.degrees(got[:, 2]) % 360, planned[:, 2] % 360, atol=0.05)  # rounded to 1e-3 rad
    g1 = [e["t_s"] for e in res["events"] if e["kind"] in ("G_1", "retarget")]
    if data["retargeted"] is not None:
        assert g1 and data["retarget_t"] == pytest.approx(g1[0])
        after = np.array([x["goal_after_G1"] for x in res["robots"]], dtype=float)
        assert np.allclose(np.array(data["retargeted"])[:, :2], after[:, :2], atol=1e-3)
    assert "planned slot (x, y, heading)" in html and "re-targeted slot (x, y, heading)" in html
    assert "d.t[frame] >= d.retarget_t" in html  # drawn only from the moment G_1 formed


def test_animation_data_keeps_retargeted_slots_apart():
    from stressbots.scenario import load

    scn = load(EXAMPLE)
    t = np.array([0.0, 10.0])
    p = np.repeat(scn.starts[None], 2, axis=0)
    goals = scn.starts + np.array([100.0, 0.0, 0.0])
    moved = goals + np.array([5.0, 3.0, 0.01])
    d = animation_data(scn, t, p, goals, retargeted=moved, retarget_time_s=4.0)
    assert d["retarget_t"] == 4.0 and np.allclose(d["retargeted"], np.round(moved, 3))
    assert animation_data(scn, t, p, goals, retargeted=moved)["retargeted"] is None  # no time: not drawn
    assert animation_data(scn, t, p, goals, retargeted=goals, retarget_time_s=4.0)["retargeted"] is None  # same as planned
