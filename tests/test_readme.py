"""The README's journeys, run as written and in order, so that the README cannot go stale.

The fast test runs them from a folder laid out as a clone (the project's files linked in, the
test's own environment as `.venv`), leaving out `make` lines (set-up, which this environment
already had). The slow one clones the repository, sets it up with `make setup` in a fresh venv
and runs every line, `make` included."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import ros1_tools
import ros2_tools

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^### (?P<title>.+?)\n.*?^```(?P<lang>sh|python)\n(?P<code>.*?)^```",
                   re.M | re.S)


def journeys(readme: str) -> list[tuple[str, str, str]]:
    """(title, language, code) of each block of the README's "Journeys" section, in order."""
    section = readme.split("\n## Journeys\n", 1)[1].split("\n## ", 1)[0]
    found = [(m["title"], m["lang"], m["code"]) for m in BLOCK.finditer(section)]
    assert len(found) == section.count("\n```") // 2, "a block outside the '### ' pattern"
    return found


def run_journeys(folder: Path, with_make: bool) -> dict[str, str]:
    # a ROS 2 graph of the test's own, on this machine only (domains 1-50: the node tests'
    # graphs, which may run beside this in another test process, take 51-100)
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "ROS_DOMAIN_ID": str(os.getpid() % 50 + 1),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    for var in ("ROS_MASTER_URI", "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "VIRTUAL_ENV"):
        env.pop(var, None)
    out = {}
    for title, lang, code in journeys((ROOT / "README.md").read_text()):
        if "ROS 1" in title and ros1_tools.missing() or "ROS 2" in title and \
                ros2_tools.missing_tf():
            continue                  # ROS cannot be had here; its own tests say why
        if lang == "python":
            cmd = [str(folder / ".venv/bin/python"), "-c", code]
        else:
            lines = [ln for ln in code.splitlines() if with_make or not ln.startswith("make ")]
            cmd = ["bash", "-e", "-c", "\n".join(lines)]
        # a session of its own, so that nothing a block starts (a roscore) outlives it
        p = subprocess.Popen(cmd, cwd=folder, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            stdout, stderr = p.communicate(timeout=900)
        finally:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        assert p.returncode == 0, f"{title}:\n{stdout[-2000:]}\n{stderr[-3000:]}"
        out[title] = stdout
    return out


def check_outputs(folder: Path, said: dict[str, str]) -> None:
    runs = folder / "runs"
    for path in ("sim/report.md", "sim/metrics.json", "bags/W2.bag", "w2.png",
                 "W2_updated.yaml", "W2.tum", "W2_mapped.yaml", "case1/truth.npz",
                 "case1_updated.yaml", "watched.rrd", "gen3.yaml", "gen3_fuse/report.md",
                 "study_small/results.csv", "study_small/summary.md"):
        assert (runs / path).exists(), path
    scores = said["Does it find changes on your recordings?"]
    assert "removed" in scores and "added" in scores
    versions = said["Map versions for a fleet: review and roll back"]
    assert "v2  approved        v1" in versions and (runs / "site.yaml").exists()
    if not ros1_tools.missing():
        assert (runs / "live.yaml").exists()
    if not ros2_tools.missing_tf():
        assert (runs / "live2.yaml").exists()
        assert "success: saved" in said["Live on a ROS 2 robot: the lifecycle node, beside Nav2"]


def test_the_readme_journeys_run_as_written(tmp_path):
    for entry in ROOT.iterdir():
        if entry.name not in (".git", ".venv", "runs") and not entry.name.startswith("."):
            (tmp_path / entry.name).symlink_to(entry)
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))
    if (ROOT / ".venv-ros2").exists():
        (tmp_path / ".venv-ros2").symlink_to(ROOT / ".venv-ros2")
    said = run_journeys(tmp_path, with_make=False)
    check_outputs(tmp_path, said)


@pytest.mark.slow
def test_the_readme_journeys_run_in_a_fresh_clone(tmp_path):
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
    setup = subprocess.run(["make", "setup"], cwd=clone, capture_output=True, text=True,
                           timeout=3600)
    assert setup.returncode == 0, setup.stderr[-3000:]
    said = run_journeys(clone, with_make=True)
    check_outputs(clone, said)
