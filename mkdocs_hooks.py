"""MkDocs hooks: the examples page is executed at build time (``make docs``).

Every ```` ```python ```` block of ``docs/examples.md`` (the README's examples) runs in order in
one namespace, in a scratch folder, with ``../shared/data`` pointed at the data folder
(``$JAXPARAM_DATA``, else ``../shared/data`` beside the repository); what a block prints is
inserted under it as a ```` ```text ```` block.  A block that raises fails the build, so the page
can only show code that runs.  Without the data folder the page is left as written and says so.
"""
from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
BLOCK = re.compile(r"```python\n(.*?)```\n", flags=re.S)


def _data() -> Path:
    return Path(os.environ.get("JAXPARAM_DATA") or ROOT.parent / "shared" / "data").resolve()


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != "examples.md":
        return markdown
    data = _data()
    if not data.exists():
        return markdown + (f"\n\n!!! note\n    Not executed: the data folder {data} is absent "
                           "(set JAXPARAM_DATA).\n")
    os.environ.setdefault("JAXPARAM_PROGRESS", "0")
    import matplotlib

    matplotlib.use("Agg")                     # the build draws no window; figures are saved
    ns: dict = {"__name__": "__main__"}
    out: list[str] = []
    pos = 0
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as scratch:
        os.chdir(scratch)
        try:
            for i, m in enumerate(BLOCK.finditer(markdown)):
                code = m.group(1).replace("../shared/data", str(data))
                buf = io.StringIO()
                with contextlib.redirect_stdout(buf):
                    exec(compile(code, f"docs/examples.md[python block {i}]", "exec"), ns)
                out.append(markdown[pos:m.end()])
                printed = buf.getvalue().replace(str(data), "../shared/data")
                if printed.strip():
                    out.append("\nOutput:\n\n```text\n" + printed.rstrip() + "\n```\n")
                pos = m.end()
        finally:
            os.chdir(cwd)
            import matplotlib.pyplot as plt

            plt.close("all")
    out.append(markdown[pos:])
    return "".join(out)
