"""Write the tutorials that are also notebooks as ``.ipynb`` files.

The tutorial pages are the notebooks' source (jupytext's Markdown format:
each page starts with a jupytext header, every ```python fence is a code
cell); shell commands stay as text, so running the notebook never installs
or starts anything. ``python docs/notebooks.py [OUT]`` writes them into
``OUT`` (default ``docs/notebooks/``) to open in Jupyter; the test suite
runs them in a kernel.
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent

#: the pages that are also notebooks
PAGES = ["getting-started.md", "tutorial-diagram.md", "tutorial-scale.md",
         "labs/lab1.md", "labs/lab2.md", "labs/lab3.md", "labs/lab4.md",
         "labs/lab5.md", "labs/lab6.md", "labs/lab7.md",
         "labs/lab8.md"]


def notebook(page: str):
    """The notebook of a tutorial page (a ``nbformat`` node)."""
    import jupytext
    from nbformat.v4 import new_markdown_cell
    nb = jupytext.read(DOCS / page, fmt="md")
    cells = []
    for c in nb.cells:
        if c.cell_type == "code" and c.source.startswith("%%"):
            magic, _, body = c.source.partition("\n")
            lang = magic[2:].split()[0] if magic[2:].strip() else ""
            cells.append(new_markdown_cell(f"```{lang}\n{body}\n```"))
        else:
            cells.append(c)
    nb.cells = cells
    return nb


def main(out=None) -> None:
    import nbformat
    out = Path(out) if out else DOCS / "notebooks"
    out.mkdir(parents=True, exist_ok=True)
    for page in PAGES:
        path = out / (Path(page).stem + ".ipynb")
        nbformat.write(notebook(page), path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main(*sys.argv[1:2])
