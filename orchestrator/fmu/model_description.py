"""Post-processing of pythonfmu's ``modelDescription.xml``: units and initial unknowns.

pythonfmu 0.7.0 writes neither ``unit`` attributes nor ``<UnitDefinitions>``
nor ``<ModelStructure><InitialUnknowns>``; without the latter every output
with the default ``initial="calculated"`` makes the FMU invalid. The
functions here add them from the component's own variable declarations and
rewrite the archive.
"""
from __future__ import annotations

import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Iterable

from fmus_src.component import Variable
from fmus_src.units import unit as lookup_unit

from .errors import FMUError

#: SI base-unit exponents of the dimension letters used by :mod:`fmus_src.units`.
_BASE_EXPONENTS: dict[str, dict[str, int]] = {
    "L": {"m": 1},
    "T": {"s": 1},
    "M": {"kg": 1},
    "I": {"A": 1},
    "A": {"rad": 1},
    "F": {"kg": 1, "m": 1, "s": -2},
    "P": {"kg": 1, "m": 2, "s": -3},
    "K": {"K": 1},
}
_TOKEN = re.compile(r"(KRW|[A-Z])(\d*)")
#: Order of the attributes of ``<BaseUnit>`` in the FMI 2.0 schema.
_BASE_ORDER = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def base_unit_exponents(dimension: str) -> dict[str, int] | None:
    """SI base-unit exponents of a dimension signature of :mod:`fmus_src.units`.

    Parameters
    ----------
    dimension : str
        e.g. ``"F.T/L"`` (N·s/m) or ``"ML2"`` (kg·m²).

    Returns
    -------
    dict or None
        ``{"kg": 1, "s": -1}`` for ``"F.T/L"``; ``{}`` for ``"1"``; None when
        the dimension has no SI expression (currency).
    """
    if dimension == "1":
        return {}
    out: dict[str, int] = {}
    numerator, _, denominator = dimension.partition("/")
    for part, sign in ((numerator, 1), (denominator, -1)):
        if part in ("", "1"):
            continue
        for letter, power in _TOKEN.findall(part.replace(".", "")):
            if letter not in _BASE_EXPONENTS:
                return None
            for base, exp in _BASE_EXPONENTS[letter].items():
                out[base] = out.get(base, 0) + sign * exp * int(power or 1)
    return {k: v for k, v in out.items() if v != 0}


def _unit_element(symbol: str) -> ET.Element:
    element = ET.Element("Unit", {"name": symbol})
    info = lookup_unit(symbol)
    exponents = base_unit_exponents(info.dimension)
    if exponents is not None:
        attrib = {k: str(exponents[k]) for k in _BASE_ORDER if k in exponents}
        if info.factor != 1.0:
            attrib["factor"] = repr(info.factor)
        ET.SubElement(element, "BaseUnit", attrib)
    return element


def annotate_model_description(xml_text: bytes | str, variables: Iterable[Variable]) -> bytes:
    """Add units, ``<UnitDefinitions>`` and ``<InitialUnknowns>`` to a pythonfmu description.

    Parameters
    ----------
    xml_text : bytes or str
        ``modelDescription.xml`` as written by pythonfmu.
    variables : iterable of Variable
        The component's declarations (names must match the scalar variables).

    Returns
    -------
    bytes
        The new ``modelDescription.xml`` (UTF-8).

    Raises
    ------
    FMUError
        A scalar variable has no declaration or vice versa.
    """
    root = ET.fromstring(xml_text)
    declared = {v.name: v for v in variables}
    model_variables = root.find("ModelVariables")
    if model_variables is None:
        raise FMUError("modelDescription.xml has no <ModelVariables>")
    used_units: list[str] = []
    output_indices: list[int] = []
    seen: set[str] = set()
    for index, scalar in enumerate(model_variables.findall("ScalarVariable"), start=1):
        name = scalar.get("name", "")
        if name not in declared:
            raise FMUError(f"modelDescription.xml: scalar variable {name!r} is not declared by the component")
        seen.add(name)
        var = declared[name]
        if var.type == "Real":
            real = scalar.find("Real")
            # "1" too: an FMU variable without a unit is *undeclared* (unknown) to an importer, not dimensionless
            if real is not None and var.unit is not None:
                real.set("unit", var.unit)
                if var.unit not in used_units:
                    used_units.append(var.unit)
        if var.causality == "output" and scalar.get("initial") in (None, "calculated", "approx"):
            output_indices.append(index)
    missing = sorted(set(declared) - seen)
    if missing:
        raise FMUError(f"modelDescription.xml: declared variables {missing} are missing")

    if used_units:
        for old in root.findall("UnitDefinitions"):
            root.remove(old)
        definitions = ET.Element("UnitDefinitions")
        for symbol in used_units:
            definitions.append(_unit_element(symbol))
        # schema order: CoSimulation, UnitDefinitions, TypeDefinitions, LogCategories, ...
        position = next(i for i, child in enumerate(root) if child.tag in ("CoSimulation", "ModelExchange")) + 1
        root.insert(position, definitions)

    structure = root.find("ModelStructure")
    if structure is None:
        structure = ET.SubElement(root, "ModelStructure")
    for old in structure.findall("InitialUnknowns"):
        structure.remove(old)
    if output_indices:
        unknowns = ET.SubElement(structure, "InitialUnknowns")
        for index in output_indices:
            # no "dependencies" attribute: may depend on every input and parameter (conservative)
            ET.SubElement(unknowns, "Unknown", {"index": str(index)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def rewrite_member(archive: Path, member: str, data: bytes) -> None:
    """Replace one member of a zip archive (writes a new archive, then moves it in place)."""
    archive = Path(archive)
    with tempfile.NamedTemporaryFile(dir=archive.parent, suffix=".fmu.tmp", delete=False) as tmp:
        tmp_path = Path(tmp.name)
    try:
        with zipfile.ZipFile(archive) as src, zipfile.ZipFile(tmp_path, "w", zipfile.ZIP_DEFLATED) as dst:
            for info in src.infolist():
                if info.filename == member:
                    continue
                dst.writestr(info, src.read(info.filename))
            dst.writestr(member, data)
        shutil.move(tmp_path, archive)
    finally:
        tmp_path.unlink(missing_ok=True)
