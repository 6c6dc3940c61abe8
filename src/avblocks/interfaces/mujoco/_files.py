"""The files an MJCF file makes MuJoCo read, checked to lie in one folder.

MuJoCo resolves the files a model names itself, relative to the main
file's folder (MuJoCo XML reference, ``include``, ``compiler/meshdir``):

* ``<include file>``, recursively (MuJoCo finds a nested include from the
  main file's folder or from the including file's folder);
* ``<compiler meshdir texturedir assetdir>``: the folders asset files are
  looked up in (an absolute one is used as it is);
* every attribute whose name starts with ``file``: ``mesh``, ``hfield``,
  ``skin`` (``asset`` and ``deformable``) and ``flexcomp`` ``file``;
  ``texture`` ``file`` and its cube faces ``fileright``, ``fileleft``,
  ``fileup``, ``filedown``, ``filefront``, ``fileback``; ``asset/model``
  ``file`` (a sub-model, whose own files are checked the same way from
  its folder).

:func:`check_mjcf_files` reads the XML with the standard library before
MuJoCo reads anything and refuses every name that leaves the folder: an
absolute path elsewhere, ``..`` out, a symbolic link that points out. A
name is resolved against every folder MuJoCo may join it to (the main
file's and the naming file's folders, each with and without each
``*dir`` of the model), and all of those must stay inside: a strict
superset of MuJoCo's own lookups. A file that declares a DOCTYPE, entities
or an XML namespace is refused: the standard library's reader and
MuJoCo's would not see the same elements.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ...core.errors import ParameterError

_NAME = "Scene"
_DIR_ATTRS = ("meshdir", "texturedir", "assetdir")


def _outside(path: Path, folder: Path) -> bool:
    return path != folder and folder not in path.parents


class _Check:
    """One walk over a model's files (``folder`` resolved)."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.seen: set[Path] = set()
        self.read: list[Path] = []

    def _rel(self, p: Path) -> str:
        try:
            return str(p.relative_to(self.folder))
        except ValueError:
            return str(p)

    def _refuse(self, file, tag, attr, value, why="names a file outside the folder"):
        raise ParameterError(
            f"<{tag} {attr}=\"{value}\"> in '{self._rel(file)}' {why} '{self.folder}'",
            block=_NAME, param="mjcf",
            hint="an MJCF scene and every file it includes or loads (meshes, "
                 "textures, height fields, skins, sub-models) must lie under the "
                 "scenario file's folder")

    def _parse(self, file: Path):
        try:
            text = file.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise ParameterError(f"cannot read '{self._rel(file)}': {e}", block=_NAME,
                                 param="mjcf") from None
        if "<!DOCTYPE" in text or "<!ENTITY" in text:
            raise ParameterError(f"'{self._rel(file)}' declares a DOCTYPE or entities, "
                                 "which MJCF does not use", block=_NAME, param="mjcf")
        if "xmlns" in text:
            # ElementTree would name <include xmlns="u"> "{u}include" and the
            # walk would miss it; MuJoCo's reader knows no namespaces and
            # includes it
            raise ParameterError(f"'{self._rel(file)}' declares an XML namespace "
                                 "(xmlns), which MJCF does not use", block=_NAME,
                                 param="mjcf")
        try:
            return ET.fromstring(text)
        except ET.ParseError as e:
            raise ParameterError(f"'{self._rel(file)}' is not well-formed XML: {e}",
                                 block=_NAME, param="mjcf") from None

    def _candidates(self, bases, dirs, value):
        for base in bases:
            for d in ("", *dirs):
                yield (base / d / value).resolve()

    def model(self, main: Path):
        """Check the model whose main file is ``main`` (inside the folder)."""
        if main in self.seen:
            return
        self.seen.add(main)
        root = self._parse(main)
        if root.tag != "mujoco":
            raise ParameterError(f"'{self._rel(main)}' is not MJCF (its root element is "
                                 f"<{root.tag}>, not <mujoco>)", block=_NAME, param="mjcf")
        self.read.append(main)
        docs = [(main, root)]
        base = main.parent
        i = 0
        while i < len(docs):                   # includes, breadth first
            file, r = docs[i]
            i += 1
            for el in r.iter("include"):
                value = el.get("file")
                if value is None:
                    continue
                for c in self._candidates({base, file.parent}, (), value):
                    if _outside(c, self.folder):
                        self._refuse(file, "include", "file", value)
                    if c.is_file() and c not in self.seen:
                        self.seen.add(c)
                        self.read.append(c)
                        docs.append((c, self._parse(c)))
        dirs = []
        for file, r in docs:
            for el in r.iter("compiler"):
                for attr in _DIR_ATTRS:
                    value = el.get(attr)
                    if value is None:
                        continue
                    for c in self._candidates({base, file.parent}, (), value):
                        if _outside(c, self.folder):
                            self._refuse(file, "compiler", attr, value,
                                         why="names a folder outside the folder")
                    dirs.append(value)
        subs = []
        for file, r in docs:
            for el in r.iter():
                if el.tag == "include":
                    continue
                for attr, value in el.attrib.items():
                    if not attr.startswith("file"):
                        continue
                    found = []
                    for c in self._candidates({base, file.parent}, dirs, value):
                        if _outside(c, self.folder):
                            self._refuse(file, el.tag, attr, value)
                        if c.is_file():
                            found.append(c)
                    if el.tag == "model" and found:
                        subs.append(found[0])
        for s in subs:                          # a sub-model: its own folder
            self.model(s)


def check_mjcf_files(path, folder) -> list[Path]:
    """The MJCF file ``path`` and the XML files it includes (resolved),
    after checking that they and every file they name lie under
    ``folder``; a :class:`~avblocks.core.errors.ParameterError` naming
    the file, the element, the attribute and the path otherwise. Reads
    only XML files inside ``folder``; MuJoCo is not called."""
    folder = Path(folder).resolve()
    main = Path(path).resolve()
    if _outside(main, folder):
        raise ParameterError(f"the MJCF file '{path}' is outside the folder '{folder}'",
                             block=_NAME, param="mjcf")
    walk = _Check(folder)
    walk.model(main)
    return walk.read
