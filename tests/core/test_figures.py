"""Report figures are drawn without pyplot, so a worker thread may draw them."""

import subprocess
import sys
import textwrap


def test_agg_figure_draws_from_a_worker_thread_without_pyplot(tmp_path) -> None:
    png = tmp_path / "fig.png"
    code = textwrap.dedent(f"""
        import sys, threading
        from effortface.core.figures import agg_figure

        def draw():
            fig = agg_figure((3, 2), layout="constrained")
            ax = fig.subplots(1, 1)
            ax.plot([0, 1, 2], [0, 1, 0])
            fig.savefig({str(png)!r}, dpi=50)

        t = threading.Thread(target=draw)
        t.start()
        t.join(60)
        assert not t.is_alive()
        print("pyplot" if "matplotlib.pyplot" in sys.modules else "no pyplot")
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "no pyplot"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
