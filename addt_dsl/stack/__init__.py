"""The AD stack under test: nodes on a timed bus. Importing registers the built-in stacks."""

from addt_dsl.stack.bev import BevStack, StackError

__all__ = ["BevStack", "StackError"]
