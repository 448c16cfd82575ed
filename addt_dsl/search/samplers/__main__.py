"""`python -m addt_dsl.search.samplers`: the registry's samplers as a Markdown table
(docs/falsify-and-shrink.md shows it; docs/regen.py regenerates it)."""

from addt_dsl.search.samplers import markdown_table

print(markdown_table(), end="")
