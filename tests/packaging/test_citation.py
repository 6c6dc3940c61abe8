"""LICENSE and CITATION.cff say what pyproject.toml and the package say.

CITATION.cff was validated against the CFF 1.2.0 schema with
``cffconvert --validate`` (cffconvert 2.0.0, in a separate environment: it
pins jsonschema < 4); here its required keys (the 1.2.0 specification:
``cff-version``, ``message``, ``title``, ``authors``; every reference a
``type``, ``title`` and ``authors``) and its agreement with the project."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml

import avblocks

ROOT = Path(__file__).resolve().parents[2]


def test_license_is_the_bsd_3_clause_text_pyproject_names():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "BSD-3-Clause" and meta["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License\n\nCopyright (c) 2026, the avblocks developers")
    for clause in ("Redistributions of source code must retain",
                   "Redistributions in binary form must reproduce",
                   "Neither the name of the copyright holder",
                   'THIS SOFTWARE IS PROVIDED BY THE COPYRIGHT HOLDERS AND CONTRIBUTORS "AS IS"'):
        assert clause in text


def test_citation_file_has_the_required_keys_and_cites_the_paper():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0"
    for key in ("message", "title", "authors"):
        assert cff[key]
    assert all("name" in a or "family-names" in a for a in cff["authors"])
    assert cff["version"] == avblocks.__version__
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert cff["license"] == meta["license"]
    (paper,) = cff["references"]
    assert paper["type"] and paper["authors"]
    assert paper["title"] == "AVLib: A Simulink Library for Multi-Agent Systems Research"
