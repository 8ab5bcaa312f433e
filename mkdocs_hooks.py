"""MkDocs hooks of the docs site (mkdocs.yml `hooks:`).

`exclude_docs` alone keeps an excluded file out of the site but reports a link to it only as INFO, which
`--strict` lets pass: a page would link a file the site does not have. Dropping the excluded files from the
build makes such a link "not found", a warning, and the strict build fails on it.
"""

from __future__ import annotations


def on_files(files, config):
    for file in [f for f in files if f.inclusion.is_excluded()]:
        files.remove(file)
    return files
