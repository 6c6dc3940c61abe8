"""Meta-tests over every public block (python-control style): each documents
its ports and every constructor parameter, and rejects unknown keywords."""

import importlib
import inspect

import pytest

from avblocks.scenarios import block_registry

REGISTRY = sorted(block_registry().items())


@pytest.mark.parametrize("name,cls", REGISTRY, ids=[k for k, _ in REGISTRY])
def test_block_documents_ports_and_parameters(name, cls):
    doc = (cls.__doc__ or "") + (cls.__init__.__doc__ or "")
    module_doc = importlib.import_module(cls.__module__).__doc__ or ""
    assert "Ports" in doc or "Ports" in module_doc, f"{name}: no Ports section"
    missing = [p for p in inspect.signature(cls.__init__).parameters
               if p != "self" and p not in doc + module_doc]
    assert not missing, f"{name}: parameters not documented: {missing}"


@pytest.mark.parametrize("name,cls", REGISTRY, ids=[k for k, _ in REGISTRY])
def test_block_rejects_unknown_keywords(name, cls):
    sig = inspect.signature(cls.__init__)
    if not any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values()):
        return          # a closed signature: Python itself rejects unknown keywords
    # blocks taking **options forward them to a closed signature or check them
    # on construction: a misspelt keyword never passes silently
    required = {"n": 2, "radius": 1.0}
    args = {k: required[k] for k, p in sig.parameters.items()
            if k != "self" and p.default is p.empty and p.kind != p.VAR_KEYWORD}
    with pytest.raises(TypeError, match="not_a_parameter_of_any_block"):
        cls(**args, not_a_parameter_of_any_block=1)
