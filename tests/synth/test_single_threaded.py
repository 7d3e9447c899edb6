"""Tasks run with every BLAS and OpenMP pool at one thread, also pools loaded after the first task."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from tests.conftest import ROOT


def test_a_library_loaded_after_the_first_task_is_limited_too() -> None:
    """OpenCV brings an OpenBLAS of its own: a task after ``import cv2`` sees it at one thread (the
    controller was once cached by module count and could miss it: serial and worker fits then differed)."""
    code = textwrap.dedent("""
        import json
        from threadpoolctl import threadpool_info
        from effortface.synth.parallel import single_threaded
        import sys
        before = single_threaded(threadpool_info)
        n_modules = len(sys.modules)
        import cv2  # noqa: F401  (its own OpenBLAS)
        # as many modules as at the first task (tests and plug-ins come and go): a cache keyed by the
        # module count would hand back the pools of the first task
        saved = {name: sys.modules.pop(name) for name in list(sys.modules)[n_modules:]}
        after = single_threaded(threadpool_info)
        sys.modules.update(saved)
        print(json.dumps({"before": [i["filepath"] for i in before],
                          "after": [(i["filepath"], i["num_threads"]) for i in after]}))
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120,
                          check=True)
    found = json.loads(done.stdout)
    new = [(path, n) for path, n in found["after"] if path not in found["before"]]
    assert all(n == 1 for _, n in found["after"]), found["after"]
    print(f"pools loaded after the first task: {new}")
