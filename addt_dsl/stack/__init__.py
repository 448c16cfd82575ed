"""The AD stack under test: nodes on a timed bus. Importing registers the built-in stacks."""

from addt_dsl.stack.bev import BevStack, StackError
from addt_dsl.stack.bridge import ExternalStack

__all__ = ["BevStack", "ExternalStack", "StackError"]
