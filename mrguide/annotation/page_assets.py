"""The annotation page's JavaScript from npm: which files of `node_modules` the page loads, found from its
import map and the modules' own imports; used by the wheel build (which ships exactly those, with the
packages' licences) and by the server (which refuses to start without them). Standard library only: the
build imports it before anything is installed.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

#: `import … from 'x'`, `export … from 'x'`, `import 'x'` and `import('x')` with a literal specifier.
_IMPORT = re.compile(r"""(?:\bfrom\s*|\bimport\s*\(?\s*)(['"])([^'"\n]+)\1""")
_IMPORT_MAP = re.compile(r'<script type="importmap">(.*?)</script>', re.S)
MODULES = "node_modules"
#: Where a built package's licence may be, beside its package.json.
LICENCES = ("LICENSE", "LICENSE.md", "LICENSE.txt", "LICENCE")


def import_map(web_dir: Path) -> dict[str, str]:
    """The page's import map (index.html): bare specifier (or prefix ending in /) → URL path."""
    html = (web_dir / "index.html").read_text()
    found = _IMPORT_MAP.search(html)
    return json.loads(found.group(1))["imports"] if found else {}


def _resolve(spec: str, importer: Path, web_dir: Path, imports: dict[str, str]) -> Path | None:
    """The file a module specifier names, or None for one outside the page (a URL, an unmapped name)."""
    if spec.startswith((".", "/")) and not spec.startswith("//"):
        return (importer.parent / spec).resolve() if spec.startswith(".") else _from_url(spec, web_dir)
    if spec in imports:
        return _from_url(imports[spec], web_dir)
    for prefix, url in imports.items():
        if prefix.endswith("/") and spec.startswith(prefix):
            return _from_url(url + spec[len(prefix) :], web_dir)
    return None


def _from_url(url: str, web_dir: Path) -> Path | None:
    if url.startswith("/static/"):
        return (web_dir / url[len("/static/") :]).resolve()
    if url.startswith(f"/{MODULES}/"):
        return (web_dir / url.lstrip("/")).resolve()
    return None


def module_files(web_dir: Path) -> list[Path]:
    """Every file under web_dir/node_modules the page can load — the closure of its scripts' imports through the
    import map — and the licence of each package among them, sorted. Raises FileNotFoundError naming the first
    file that an import needs and that is not there (`npm ci` not run)."""
    web_dir = web_dir.resolve()
    imports = import_map(web_dir)
    todo = [p for p in web_dir.glob("*.js")] + [
        f
        for spec in imports
        for f in [_resolve(spec, web_dir / "index.html", web_dir, imports)]
        if f is not None and not spec.endswith("/")
    ]
    seen: set[Path] = set()
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        if not path.is_file():
            raise FileNotFoundError(f"the annotation page needs {path}, which is not there")
        seen.add(path)
        for _, spec in _IMPORT.findall(path.read_text(encoding="utf-8", errors="replace")):
            target = _resolve(spec, path, web_dir, imports)
            if target is not None:
                todo.append(target)
    modules = web_dir / MODULES
    files = {p for p in seen if p.is_relative_to(modules)}
    for package in {modules / p.relative_to(modules).parts[0] for p in files}:
        files.update(package / name for name in LICENCES if (package / name).is_file())
    return sorted(files)


def missing(web_dir: Path) -> str | None:
    """Why the page cannot load its scripts (a file of the module graph is missing), or None."""
    try:
        module_files(web_dir)
    except FileNotFoundError as exc:
        return str(exc)
    return None
