"""Check that nothing of the README was lost when it became the guide.

Every non-blank line of the README as it was before the guide (``git show OLD:README.md``) must
appear, word for word, in some page under ``docs/`` (words compared without case and punctuation;
issue numbers, which the guide no longer cites, words that dated a line to its round ("new",
"change") and the package path words that the layout change renamed are ignored). Lines that the new layout made false are listed in :data:`SUPERSEDED` with
the page that says what is true now. Exit status 1 lists the lines not found; the test skips when
the old README's commit is not in the clone (a shallow clone).

Usage: ``python tools/readme_in_guide.py [--rev COMMIT]``

restructure: keep old names (the old README's lines are quoted as they were)
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the last commit whose README held the whole reference
OLD_README_REV = "12e8ca2"
#: words that name packages or folders the layout change renamed (train/motion.py -> effortface/synth/motion.py)
PATH_WORDS = {"docs", "effortface", "synth", "interop", "train", "capture_tool", "annotate", "core", "session", "folder", "py"}
#: words that dated a line to the round of work that made it ("(new)", "Change:", "is now"), which the
#: guide no longer says (what changed, and when, is in CHANGELOG.md)
DATING_WORDS = {"new", "change", "now"}
#: start of README lines the new layout made false -> where the guide says what is true now
SUPERSEDED = {
    "`motion/mocap.csv`, and `--video FILE` with `--video-stream NAME`": "guide/interop.md (the mocap clip attached)",
    "`video.avi` (MJPG, written through OpenCV's own MJPEG writer": "guide/capture.md (its own streaming AVI writer)",
    "A `session.json` written before this table with an age": "guide/capture.md (an age outside 10-100)",
    "naming the field. The folder holds": "guide/capture.md",
    "exits quietly with status 0 (it used to claim that no program": "guide/capture.md (replay)",
    "had opened the port); pointing a fixed symlink": "guide/capture.md (replay)",
    "| `effortface/core/`": "guide/layout.md (the new table)",
    "| `capture_tool/`": "guide/layout.md",
    "| `annotate/`": "guide/layout.md",
    "| `train/`": "guide/layout.md",
    "| `effortface/`": "guide/layout.md",
    "| `effortface/samplelab/`": "guide/layout.md",
    "| `sample_sessions/`": "guide/layout.md",
    "| `runtime-dist/`": "guide/layout.md",
    "| `tests/`": "guide/layout.md",
    "| `benchmarks/`": "guide/layout.md",
    "| folder | installed as": "guide/layout.md",
    "|---|---|---|---|": "guide/layout.md",
    "code. The stage folders keep their place": "guide/layout.md (no links now)",
    "`effortface/capture_tool -> ../capture_tool`": "guide/layout.md (no links now)",
    "`effortface/train -> ../train`, so setuptools": "guide/layout.md (no links now)",
    "tree. Change (not backward compatible": "guide/layout.md (What moved)",
    "`train.runtime` is now `effortface.runtime`": "guide/layout.md (What moved)",
    "`effortface.capture_tool.x`, and so on": "guide/layout.md (What moved)",
    "Architecture rules, checked by import-linter": "guide/layout.md (The rooms and their order)",
    "`tests/test_import_rules.py`: data flows one way": "guide/layout.md (The rooms and their order)",
    "front door (`cli`, `app`, `commands`, `runtime`)": "guide/layout.md (The rooms and their order)",
    "`effortface.runtime` and everything it imports use": "guide/layout.md (The rooms and their order)",
    "(`*/commands/*.py`) only parse options": "guide/layout.md (The rooms and their order)",
    "`effortface/cli.py` imports one.": "guide/layout.md (The rooms and their order)",
    # the runtime example used names it never defined: it is now one that runs (tests/test_docs_examples.py)
    "from effortface.runtime import load_model, Character, motion_from_positions": "guide/synthesize.md",
    "curves = model.synthesize(\"clip.bvh\"": "guide/synthesize.md",
    "training_level=5, expressiveness=(1, 1, 1, 1)))": "guide/synthesize.md",
    "skeleton = motion_from_positions(rest_pose_m": "guide/synthesize.md",
    "live = model.stream(character, skeleton)": "guide/synthesize.md",
    "weights = live.step(joint_positions_m, dt_s)": "guide/synthesize.md",
    "crowd = model.stream_batch(characters, skeleton)": "guide/synthesize.md",
    "weights_n = crowd.step(positions_m_n, dt_s)": "guide/synthesize.md",
    "Every screenshot of this README is retaken": "guide/app.md (this guide)",
    # the main job installs what it needs, not the test tools
    "    python -m pip install -e '.[test]' && effortface demo": "guide/getting-started.md (pip install -e .)",
    "(`.ci/run` does exactly the second, after installing": "guide/getting-started.md (and builds the guide)",
    # reworded only to drop an issue number
    "Output filter (new in issue 18, on by default)": "guide/synthesize.md (new, on by default)",
    "exact: 1,300; before issue 15's work here": "guide/synthesize.md (before the scaling work)",
    # figures re-measured like for like (median frames) or behaviour changed since the old README
    "CPU, and takes 0.73x the serial time": "guide/train.md (re-measured: median of 3 runs)",
    "seeks land on the right frame, trims `video_frames.csv`": "guide/capture.md (frames copied byte for byte)",
    "support vector (2,500 characters x 9,000 vectors": "guide/synthesize.md (re-measured)",
    "exact): `single_precision=True` evaluates the kernels in float32, about 2x": "guide/synthesize.md",
    # figures of the shipped lab that the lab's regeneration changed: the guide states today's, checked
    # against the lab by tests/test_docs_figures.py; and behaviour since changed (skips, local stand-ins)
    "Change (engine-ready): `face.onnx` is now": "guide/train.md (For engines, `face.onnx` is)",
    # lines that dated a fact to the change that made it ("used to", "before:", "since this release"): the
    # pages say what is, CHANGELOG.md what changed
    'metadata, checked against the numpy runtime at export:': "guide/train.md",
    '(change: a float32 difference up to 2e-3 used to be': "guide/train.md",
    'measures 3e-5 (the previous graph, 7.5e-4); the': "guide/train.md",
    'the float64 graph (previously `face.onnx`, opset 17) is': "guide/train.md",
    'write curves with `effortface.train.curves_io.write_curves`. Change': "guide/train.md",
    'line and the files are unchanged): `run_training` moved': "guide/train.md",
    '`effortface.train.pipeline` (it takes a': "guide/train.md",
    '`LIVELINK_BLENDSHAPES`...) to': "guide/train.md",
    '`per_participant_in_sample` is the former in-sample': "guide/train.md",
    'The pooled model is renamed `pooled_threshold` (one': "guide/train.md",
    "training level; not the paper's pooled model, an": "guide/train.md",
    'key `pooled`). The report marks each score held out or': "guide/train.md",
    '`svr_known_expressiveness` (new rows) uses their own': "guide/train.md",
    'Change (stricter, so that `--force` can never lose': "guide/train.md",
    'participant, 1 Hz) now defaults to 3600 (one hour) and': "guide/train.md",
    'participant and 2,000 in all, which `--max-rows` could': "guide/train.md",
    'are exact RBF SVRs as before; above, every fit of the': "guide/train.md",
    'approximation (300 landmark rows drawn with a fixed': "guide/train.md",
    'epsilon does not enter it). It is stored as an SVR is': "guide/train.md",
    "Nystroem model no longer depends on the machine's core": "guide/train.md",
    "release's by about 1e-7). The training data goes to": "guide/train.md",
    'this release: 1.1-1.8x, with twice the CPU).': "guide/train.md",
    'and exit status 2, never a traceback. Since this': "guide/train.md",
    '`<name>-timing.csv` beside a raw capture is refused (it': "guide/train.md",
    'SVR C and gamma up to 1e6, `update_period_s` 0.001-60 s': "guide/train.md",
    'Files honour the umask (fixed in this release:': "guide/train.md",
    'CSVs were 0600, unreadable to colleagues on a shared': "guide/train.md",
    '--filter-tau-s S` overrides it (0 writes the raw': "guide/synthesize.md",
    "**Change to DESIGN.md's runtime API (backward": "guide/synthesize.md",
    'a game at 30, 60 or 120 fps, or with jittering frame': "guide/synthesize.md",
    "before, the window counted frames at the skeleton's": "guide/synthesize.md",
    'falling body does no work (issue 18; before, kinetic': "guide/motion-and-work.md",
    'Long clips (issue 15): the BVH reader parses and poses': "guide/motion-and-work.md",
    'before, about 3x faster), so its working memory no': "guide/motion-and-work.md",
    "about 300x with the sample lab's SVR (3.6 s, 165x,": "guide/motion-and-work.md",
    'scikit-learn, pandas, Qt, tqdm or dask (`tests/train/test_synth_cli.py` checks it)': "guide/motion-and-work.md",
    '(change: before, such a session was refused).': "guide/motion-and-work.md",
    'package (new dependency): a file that is not Plug-in': "guide/motion-and-work.md",
    'skeleton; an occluded point is refused with its name': "guide/motion-and-work.md",
    "the test labels. On the sample lab r falls from 0.96": "guide/train.md (today's figures, measured and dated)",
    "the held-out SVR r is 0.71 (0.92 with known": "guide/train.md (today's figures, measured and dated)",
    "expressiveness). `face_in_sample`": "guide/train.md",
    "Two tests skip, saying why:": "guide/getting-started.md (some tests skip, each saying why)",
    "and download PyPI's `annotate` and": "guide/getting-started.md (local stand-ins)",
    "`train` to install beside effortface.": "guide/getting-started.md (local stand-ins)",
    "in about 30 s, once, and says so on stderr in": "guide/getting-started.md (the estimate the product prints)",
    "the sample lab gives 9.3 %), ICC(A,1)": "guide/annotate.md (today's figures)",
    "flagged for review. New (issue 18): each ICC has its 95 %": "guide/annotate.md (every statistic's interval)",
    "Wong 1996; they reproduce Shrout & Fleiss 1979's published intervals and agree with pingouin), in":
        "guide/annotate.md",
    "`agreement`'s table and in the reliability panel: with 18 poses they are wide (sample lab: overall":
        "guide/annotate.md (today's figures)",
    "session of 10-12 minutes: 12 sessions, 21 MB,": "guide/sample-data.md (today's figures)",
    "one motion clip, three raters' key-frames and a": "guide/sample-data.md (3 raters, a blind round)",
    "reliability pose set; no `work.csv`, which": "guide/sample-data.md",
    "(about 27 s of CPU; a thin wrapper around": "guide/sample-data.md (re-measured)",
    "6e-8 x sum |alpha| of float64 (`SINGLE_PRECISION_ERROR_PER_ALPHA`; 8e-4": "guide/synthesize.md",
    "about 2,300 characters per core at 60 FPS": "guide/synthesize.md (3,300 by the median frame)",
    "the energies are paid); `surrogate=True`": "guide/synthesize.md",
    "on the benchmark's crowd) and the exact model outside it, about 5,000": "guide/synthesize.md",
    "blendshape) stays exact. Figures: `benchmarks/bench_scale.py` (section 4).": "guide/synthesize.md",
}


def words(text: str) -> list[str]:
    """Lower-case words, issue numbers and renamed path words left out."""
    out, skip = [], 0
    tokens = re.findall(r"[a-z0-9_]+", text.lower())
    for i, t in enumerate(tokens):
        if skip:
            skip -= 1
            continue
        if t == "issue" and i + 1 < len(tokens) and tokens[i + 1].isdigit():
            skip = 1 + (2 if i + 3 < len(tokens) and tokens[i + 2] == "item" and tokens[i + 3].isdigit() else 0)
            continue
        if t in PATH_WORDS or t in DATING_WORDS:
            continue
        out.append(t)
    return out


def missing_lines(readme: str, docs: str) -> list[str]:
    """README lines whose words do not appear, in order, in the docs (superseded ones left out)."""
    haystack = " " + " ".join(words(docs)) + " "
    out = []
    for line in readme.splitlines():
        if not line.strip() or any(line.lstrip().startswith(s.lstrip()) or s in line for s in SUPERSEDED):
            continue
        needle = " ".join(words(line))
        if needle and f" {needle} " not in haystack:
            out.append(line)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="every README line is somewhere in docs/")
    parser.add_argument("--rev", default=OLD_README_REV, help=f"commit of the old README (default {OLD_README_REV})")
    args = parser.parse_args(argv)
    old = subprocess.run(["git", "show", f"{args.rev}:README.md"], cwd=ROOT, capture_output=True, text=True)
    if old.returncode:
        print(f"readme_in_guide: commit {args.rev} not in this clone (shallow?): nothing checked")
        return 0
    docs = "\n".join(p.read_text(encoding="utf-8") for p in sorted((ROOT / "docs").rglob("*.md")))
    lost = missing_lines(old.stdout, docs)
    for line in lost:
        print(f"not in docs/: {line}")
    print(f"{len(old.stdout.splitlines())} README lines, {len(lost)} not found in docs/")
    return 1 if lost else 0


if __name__ == "__main__":
    raise SystemExit(main())
