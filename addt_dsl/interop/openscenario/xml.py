"""Reading an OpenSCENARIO document: the size limit, the tree helpers and the error that ends an import
(the line-numbered, defused XML reader itself is `addt_dsl/xmlread.py`, shared with the OpenDRIVE reader)."""

MAX_XML_BYTES = 8 * 1024 * 1024


class Stop(Exception):
    """An error that ends the import (already reported)."""


def child_at(el, *path):
    for tag in path:
        if el is None:
            return None
        el = el.find(tag)
    return el


def first_of(*elements):
    """The first element that is not None (elements without children are false)."""
    return next((e for e in elements if e is not None), None)


def only_child(el):
    kids = list(el) if el is not None else []
    return kids[0] if len(kids) == 1 else None
