"""A git revision of this repository checked out for a while, beside the working tree.

``checked_out(rev)`` makes a detached ``git worktree`` of the revision in a temporary folder
and removes it, and the folder, when the block ends: normally, on an error, on Ctrl-C, and on
SIGTERM once ``exit_on_sigterm()`` has been called. Used by ``benchmarks/run.py --baseline``
and ``tests/data/golden/record.py``.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


class RevisionError(Exception):
    """A revision that git cannot name or check out."""


def git(*args: str, repo: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True)


def resolve(rev: str, repo: Path = ROOT) -> str:
    """The full hash of the commit ``rev`` names."""
    found = git("rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}", repo=repo)
    if found.returncode or not found.stdout.strip():
        raise RevisionError(f"{rev!r} names no commit of {repo}")
    return found.stdout.strip()


def describe_working_tree(repo: Path = ROOT) -> str:
    """HEAD's short hash, and whether the working tree differs from it."""
    head = git("rev-parse", "--short", "HEAD", repo=repo).stdout.strip() or "no HEAD"
    dirty = git("status", "--porcelain", "--untracked-files=no", repo=repo).stdout.strip()
    return f"{head} with uncommitted changes" if dirty else head


@contextmanager
def checked_out(rev: str, repo: Path = ROOT):
    """Yields the path of a detached worktree of ``rev`` (its files only: no build, no
    untracked files), removed at the end."""
    commit = resolve(rev, repo)
    parent = Path(tempfile.mkdtemp(prefix=f"baseline-{commit[:10]}-"))
    tree = parent / "tree"
    try:
        added = git("worktree", "add", "--detach", "--quiet", str(tree), commit, repo=repo)
        if added.returncode:
            raise RevisionError(f"git worktree add {commit[:10]} failed: "
                                f"{' '.join(added.stderr.split())}")
        yield tree
    finally:
        if git("worktree", "remove", "--force", str(tree), repo=repo).returncode:
            shutil.rmtree(parent, ignore_errors=True)
            git("worktree", "prune", repo=repo)       # the entry of a tree that is gone
        shutil.rmtree(parent, ignore_errors=True)


def exit_on_sigterm() -> None:
    """SIGTERM ends the process as Ctrl-C does, through the ``finally`` blocks (so a worktree
    made by ``checked_out`` is removed)."""
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
