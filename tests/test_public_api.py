"""The public API: every package's ``__all__`` resolves, and importing a package stays cheap."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

PACKAGES = [
    "warp_critic",
    "warp_critic.core",
    "warp_critic.physics",
    "warp_critic.learning",
    "warp_critic.running",
    "warp_critic.methods",
    "warp_critic.evaluation",
    "warp_critic.analysis",
    "warp_critic.reproduce",
    "warp_critic.cli",
]


@pytest.mark.parametrize("name", PACKAGES)
def test_every_exported_name_resolves(name):
    package = importlib.import_module(name)
    assert package.__all__ and len(set(package.__all__)) == len(package.__all__)
    for attr in package.__all__:
        assert getattr(package, attr) is not None, f"{name}.{attr}"
    assert set(package.__all__) <= set(dir(package))
    with pytest.raises(AttributeError):
        package.no_such_name  # noqa: B018


def test_the_top_level_api_is_the_layers_objects():
    import warp_critic
    from warp_critic.evaluation.metatest import meta_test
    from warp_critic.methods.meta_critic import MetaCriticConfig, train_meta_critic
    from warp_critic.methods.ours import TrainConfig
    from warp_critic.methods.sac import SACConfig, train_sac
    from warp_critic.methods.td3 import TD3Config, train_td3

    assert warp_critic.meta_test is meta_test and warp_critic.TrainConfig is TrainConfig
    assert warp_critic.train_td3 is train_td3 and warp_critic.TD3Config is TD3Config
    assert warp_critic.train_sac is train_sac and warp_critic.SACConfig is SACConfig
    assert warp_critic.train_meta_critic is train_meta_critic
    assert warp_critic.MetaCriticConfig is MetaCriticConfig


# analysis exports one plain function, not lazily
LAZY = [p for p in PACKAGES if p != "warp_critic.analysis"]


@pytest.mark.parametrize("name", LAZY)
def test_type_checkers_see_every_lazy_export(name):
    """Each lazy ``__init__`` imports its exports under ``TYPE_CHECKING`` (for IDEs and mypy), the
    same names from the same modules as its ``lazy_exports`` table."""
    import ast
    from pathlib import Path

    package = importlib.import_module(name)
    tree = ast.parse(Path(package.__file__).read_text(encoding="utf-8"))
    guarded = [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING"
    ]
    assert len(guarded) == 1, name
    seen = {
        (imp.module, alias.name)
        for imp in guarded[0].body
        if isinstance(imp, ast.ImportFrom)
        for alias in imp.names
    }
    lazy = next(
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "lazy_exports"
    )
    table = ast.literal_eval(lazy.args[1])
    assert seen == {(module, n) for module, names in table.items() for n in names}, name
    assert {n for _, n in seen} == set(package.__all__) - {"__version__"}


@pytest.mark.subprocess
def test_importing_the_packages_imports_neither_torch_nor_warp():
    code = (
        "import sys, warp_critic, warp_critic.core, warp_critic.learning, warp_critic.evaluation, "
        "warp_critic.reproduce, warp_critic.cli; "
        "print(sorted(m for m in ('torch', 'warp', 'newton', 'numpy') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
