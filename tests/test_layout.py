"""The tests' folders mirror the package: a folder of tests per subpackage it tests (`tools/` for the probes), the
top-level modules' tests at the top."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _folders(root: Path) -> set[str]:
    return {p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}


def test_every_test_folder_is_a_folder_of_the_package_or_the_tools():
    packages = {p.name for p in (ROOT / "mrguide").iterdir() if (p / "__init__.py").exists()}
    assert _folders(ROOT / "tests") - packages - {"tools"} == set()
