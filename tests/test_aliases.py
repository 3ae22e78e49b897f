"""Old flat module paths still import, warn, and give the new modules' objects."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from activetrack._aliases import MOVED


@pytest.mark.parametrize("old", sorted(MOVED))
def test_old_path_warns_and_forwards(old):
    new = importlib.import_module(MOVED[old])
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=MOVED[old].replace(".", r"\.")):
        alias = importlib.import_module(old)
    public = [n for n in vars(new) if not n.startswith("__")]
    assert public and all(getattr(alias, n) is getattr(new, n) for n in public)


def test_from_import_of_an_old_path_in_a_fresh_interpreter():
    code = (
        "import warnings\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    from activetrack.scenarios import PRESETS\n"
        "from activetrack.world.scenarios import PRESETS as P\n"
        "assert PRESETS is P\n"
        "print(sum(issubclass(x.category, DeprecationWarning) for x in w))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"


def test_every_moved_module_exists_and_no_new_module_is_aliased():
    for old, new in MOVED.items():
        assert importlib.util.find_spec(new) is not None, new
        assert old.rsplit(".", 1)[1] not in {"world"}, "the world package keeps its name"
