"""One progress switch for the library: jp.config.progress, JAXPARAM_PROGRESS, TQDM_DISABLE,
verbose= per call; the text bar (no ipywidgets warning) in a kernel without ipywidgets."""
import sys
import types
import warnings

import pytest

import jaxparam as jp
from jaxparam import progress as prog


@pytest.fixture(autouse=True)
def fresh_switch(monkeypatch):
    monkeypatch.delenv("JAXPARAM_PROGRESS", raising=False)
    monkeypatch.delenv("TQDM_DISABLE", raising=False)
    before = jp.config.progress if jp.config._progress is not None else None
    jp.config.progress = None
    yield
    jp.config.progress = before


@pytest.mark.parametrize("env,value,on", [
    (None, None, True), ("JAXPARAM_PROGRESS", "0", False), ("JAXPARAM_PROGRESS", "off", False),
    ("JAXPARAM_PROGRESS", "1", True), ("TQDM_DISABLE", "1", False), ("TQDM_DISABLE", "0", True),
])
def test_environment_sets_the_default(monkeypatch, env, value, on):
    if env:
        monkeypatch.setenv(env, value)
    assert jp.config.progress is on
    assert prog.enabled() is on


def test_setting_overrides_the_environment_and_verbose_overrides_the_setting(monkeypatch):
    monkeypatch.setenv("TQDM_DISABLE", "1")
    jp.config.progress = True
    assert prog.enabled() and not prog.enabled(verbose=False)
    jp.config.progress = False
    assert not prog.enabled() and prog.enabled(verbose=True)
    with pytest.raises(AttributeError, match="progress"):
        jp.config.progres = False                       # a typo is an error, not a no-op


def test_bar_writes_only_when_on(capsys):
    jp.config.progress = True
    with prog.progress(total=3, desc="stage-on", delay=0) as bar:
        bar.update(3)
    assert "stage-on" in capsys.readouterr().err
    jp.config.progress = False
    with prog.progress(total=3, desc="stage-off", delay=0) as bar:
        bar.update(3)
    assert capsys.readouterr().err == ""


def test_kernel_without_ipywidgets_gets_the_text_bar_and_no_warning(monkeypatch, capsys):
    class ZMQInteractiveShell:                          # what a Jupyter kernel's shell is called
        pass

    fake = types.ModuleType("IPython")
    fake.get_ipython = lambda: ZMQInteractiveShell()
    monkeypatch.setitem(sys.modules, "IPython", fake)
    monkeypatch.setitem(sys.modules, "ipywidgets", None)          # import fails
    prog._bar_class.cache_clear()
    try:
        jp.config.progress = True
        with warnings.catch_warnings():
            warnings.simplefilter("error")               # tqdm's IProgress warning would raise
            with prog.progress(total=2, desc="kernel", delay=0) as bar:
                bar.update(2)
        from tqdm import tqdm as text_bar
        from tqdm.notebook import tqdm as notebook_bar
        assert type(bar) is text_bar and not isinstance(bar, notebook_bar)
        assert "IProgress" not in capsys.readouterr().err
    finally:
        prog._bar_class.cache_clear()


def test_minimize_follows_the_switch(monkeypatch):
    from jaxparam.optimize import base

    seen = []

    def recording(*args, **kwargs):
        seen.append(kwargs.get("verbose"))
        return prog.progress(*args, **kwargs)

    monkeypatch.setattr(base, "progress", recording)
    mesh = jp.shapes.graph_surface(5)
    jp.minimize(mesh, "symmetric_dirichlet", max_iters=3)
    jp.minimize(mesh, "symmetric_dirichlet", max_iters=3, verbose=False)
    assert seen == [None, False]                       # None: jp.config.progress decides


def test_atlas_shows_its_stages(monkeypatch, capsys):
    """jp.atlas runs for minutes on large meshes: its stages show on one bar (charts, flatten,
    pack, compact, orders), which ``verbose=False`` turns off."""
    made = []
    original = prog.progress

    def recording(*args, **kwargs):
        bar = original(*args, **{**kwargs, "delay": 0})
        made.append((kwargs.get("verbose"), bar))
        return bar

    monkeypatch.setattr(prog, "progress", recording)          # StageBar's bar factory
    mesh = jp.shapes.sphere(0)                                 # 2 charts, every stage
    jp.atlas(mesh, verbose=True)
    err = capsys.readouterr().err
    bar = made[0][1]
    assert made[0][0] is True and bar.n == bar.total == 5 and bar.postfix == "orders"
    assert "atlas:" in err
    jp.atlas(mesh, verbose=False)
    assert made[1][0] is False and capsys.readouterr().err == ""
