"""The one safe XML reader, with line numbers: OpenSCENARIO files (`addt_dsl/interop/openscenario`)
and OpenDRIVE files (`addt_dsl/road/xodr.py`) are both read here.

defusedxml's expat parser: entity declarations (billion laughs) and external entities or
DTDs are refused, nothing is fetched from the network. Each element's source line is
recorded, so that a diagnostic points at it. Callers bound the size of what they read
(they know their limits); the errors below carry what each caller words its own way.
This module is a core module: the compiler side (interop) and the runtime both import it.
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.etree.ElementTree import Element

from defusedxml import DefusedXmlException, ExternalReferenceForbidden
from defusedxml.ElementTree import DefusedXMLParser
from xml.parsers.expat import ErrorString


class XmlReadError(ValueError):
    """A document that is not read: `unsafe` (a DTD or an entity; `exception` names defusedxml's
    refusal), `decode` (an encoding Python does not have) or `malformed` (`detail`: expat's
    message with its position, `reason`: without); `line` is 1-based."""

    def __init__(self, kind: str, exception: str, detail: str, reason: str, line: int):
        super().__init__(detail)
        self.kind, self.exception, self.detail, self.reason, self.line = kind, exception, detail, reason, line


class _LineParser(DefusedXMLParser):
    """defusedxml's parser that records each element's line."""

    def __init__(self, forbid_dtd: bool):
        super().__init__(forbid_dtd=forbid_dtd, forbid_entities=True, forbid_external=True)
        self.lines: dict[int, int] = {}
        if not forbid_dtd:
            self.parser.StartDoctypeDeclHandler = self._refuse_external_dtd

    @staticmethod
    def _refuse_external_dtd(name, sysid, pubid, has_internal_subset):
        """A plain DOCTYPE is read; one that names an external DTD is refused (it is never fetched)."""
        if sysid is not None or pubid is not None:
            raise ExternalReferenceForbidden(name, None, sysid, pubid)

    def _start(self, tag, attr_list):
        element = super()._start(tag, attr_list)
        self.lines[id(element)] = self.parser.CurrentLineNumber
        return element


@dataclass(frozen=True)
class XmlDocument:
    root: Element
    lines: dict[int, int]  # id(element) -> its 1-based source line

    def line(self, element: Element) -> int:
        return self.lines.get(id(element), 1)


def read_xml(data: str | bytes, *, forbid_dtd: bool = True) -> XmlDocument:
    """The document's element tree and each element's line; XmlReadError if it is refused or
    not well-formed. `forbid_dtd=False` accepts a plain DOCTYPE (entities stay refused)."""
    parser = _LineParser(forbid_dtd)
    try:
        parser.feed(data)
        root = parser.close()
    except DefusedXmlException as exc:
        line = parser.parser.CurrentLineNumber if parser.parser is not None else 1
        raise XmlReadError("unsafe", type(exc).__name__, str(exc), str(exc), max(1, line)) from None
    except (LookupError, UnicodeError) as exc:  # `<?xml ... encoding="abc"?>`: no such codec
        line = parser.parser.CurrentLineNumber if parser.parser is not None else 1
        raise XmlReadError("decode", type(exc).__name__, str(exc), str(exc), max(1, line)) from None
    except Exception as exc:  # noqa: BLE001 - expat's ParseError, and any error on hostile input
        line = getattr(exc, "position", (1, 0))[0] if hasattr(exc, "position") else 1
        code = getattr(exc, "code", None)
        reason = ErrorString(code) if isinstance(code, int) else str(exc)
        raise XmlReadError("malformed", type(exc).__name__, str(exc), reason, max(1, line)) from None
    return XmlDocument(root, parser.lines)
