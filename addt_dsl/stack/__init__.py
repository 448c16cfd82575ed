"""The AD stack under test: nodes on a timed bus. Importing registers the built-in stacks'
implementations (their specs: `addt_dsl/specs/stacks.py`)."""

from addt_dsl.stack.bev import BevStack, StackError
from addt_dsl.stack.bridge import ExternalStack

__all__ = ["BevStack", "ExternalStack", "StackError"]
