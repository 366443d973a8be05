"""Old import paths of moved modules keep working until 0.3.0, with a warning naming the new one."""

from __future__ import annotations

import importlib
import pickle
import subprocess
import sys

import pytest

from monoplane.moved_modules import MOVED


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_path_is_the_module_at_its_new_path(old: str) -> None:
    new = importlib.import_module(MOVED[old])
    assert importlib.import_module(old) is new
    assert new.__spec__.name == MOVED[old]  # the alias leaves the module's own spec in place


def test_the_old_paths_name_no_file_and_the_new_paths_exist() -> None:
    for old, new in MOVED.items():
        assert importlib.util.find_spec(new) is not None
        assert importlib.util.find_spec(new).name == new
        assert old != new


def test_an_old_path_warns_once_with_the_new_path() -> None:
    code = ("import warnings\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            "    warnings.simplefilter('always')\n"
            "    from monoplane.fileio import load_frame\n"
            "print([str(x.message) for x in w if x.category is DeprecationWarning])\n"
            "print(load_frame.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    lines = out.stdout.splitlines()
    assert lines[0] == ("['monoplane.fileio moved to monoplane.io.frames; "
                        "the old path goes in 0.3.0']")
    assert lines[1] == "monoplane.io.frames"


def test_classes_pickle_under_their_new_path() -> None:
    from monoplane.host.pipeline import Pipeline

    assert b"monoplane.host.pipeline" in pickle.dumps(Pipeline)
    assert pickle.loads(pickle.dumps(Pipeline)) is Pipeline


def test_an_unknown_module_still_fails_as_usual() -> None:
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("monoplane.no_such_module")


def test_renamed_names_warn_and_return_the_new_object() -> None:
    import warnings

    from monoplane.deprecation import renamed_names

    getattr_ = renamed_names("pkg.old", {"old_sqrt": "math:sqrt"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import math

        assert getattr_("old_sqrt") is math.sqrt
    assert [str(w.message) for w in caught] == [
        "pkg.old.old_sqrt is now math.sqrt; the old name goes in 0.3.0"]
    with pytest.raises(AttributeError, match="module 'pkg.old' has no attribute 'other'"):
        getattr_("other")
