"""Executes a notebook headless, from a temporary folder outside the source tree (as a user who
copied it out of the checkout), writes the executed notebook into OUT_DIR and checks that it
embeds its figures: at least one image/png output (with matplotlib's Agg backend nothing is shown
unless the notebook displays the figure itself). The kernel is the interpreter that runs this
script (a virtual environment's, for the wheel), not the system's kernelspec "python3" (Debian's
/usr/bin/python3). Usage: run_notebook.py NOTEBOOK OUT_DIR"""

import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import nbformat
from nbclient import NotebookClient


def main() -> int:
    src, out_dir = Path(sys.argv[1]).resolve(), Path(sys.argv[2])
    nb = nbformat.read(src, as_version=4)
    with tempfile.TemporaryDirectory(prefix="exid-notebook-") as work:
        shutil.copy(src, work)  # the notebook alone, nothing of the checkout beside it
        spec = Path(work) / "jupyter" / "kernels" / "exid-python"
        spec.mkdir(parents=True)
        argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
        (spec / "kernel.json").write_text(json.dumps({"argv": argv, "language": "python", "display_name": "exid"}))
        os.environ["JUPYTER_PATH"] = os.pathsep.join([str(Path(work) / "jupyter"), os.environ.get("JUPYTER_PATH", "")])
        client = NotebookClient(
            nb, timeout=600, kernel_name="exid-python", resources={"metadata": {"path": work}}
        )
        client.execute()
    out_dir.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, out_dir / src.name)
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    pngs = [o for o in outputs if "image/png" in o.get("data", {})]
    htmls = [o["data"]["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    if not pngs:
        print(f"run_notebook: {src.name} embeds no image/png output (MPLBACKEND={os.environ.get('MPLBACKEND')})")
        return 1
    if not any("exid study" in h and "<img" in h for h in htmls):
        print(f"run_notebook: {src.name} shows no study result with its validation figure (_repr_html_)")
        return 1
    print(f"run_notebook: {src.name}: {len(pngs)} figure(s), executed into {out_dir / src.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
