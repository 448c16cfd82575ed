"""`python -m addt_dsl.search.samplers`: the registry's samplers as a Markdown table
(docs/falsify-and-shrink.md shows it; docs/regen.py regenerates it)."""

from addt_dsl.search.samplers import markdown_table

if __name__ == "__main__":
    print(markdown_table(), end="")
