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
    from warp_critic.methods.ours import TrainConfig

    assert warp_critic.meta_test is meta_test and warp_critic.TrainConfig is TrainConfig


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
