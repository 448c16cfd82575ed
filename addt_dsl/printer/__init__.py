"""Plans and runs back to `.addt` source (`printer.plan`), values and formulas with units
(`printer.expr`, the one formula printer). See the modules for the round-trip contracts."""

from __future__ import annotations

from addt_dsl.printer.expr import PrinterError, dim_of_name, format_const, format_expr, format_quantity
from addt_dsl.printer.plan import (check_spec, compile_pinned, params_referenced, pin_spec, pinned_fault_plan,
                                   print_plan, print_spec, semantic_key, side_files)

__all__ = ["PrinterError", "check_spec", "compile_pinned", "dim_of_name", "format_const", "format_expr",
           "format_quantity", "params_referenced", "pin_spec", "pinned_fault_plan", "print_plan", "print_spec",
           "semantic_key", "side_files"]
