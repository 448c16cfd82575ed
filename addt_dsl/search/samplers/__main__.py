"""`python -m addt_dsl.search.samplers`: the registry's samplers as a Markdown table
(docs/falsify-and-shrink.md shows it; docs/regen.py regenerates it)."""

from addt_dsl.search.samplers import DEFAULT_SAMPLER, SAMPLERS

print("| `--sampler` | what it does | implementation |")
print("| --- | --- | --- |")
for s in SAMPLERS.values():
    module, cls = s.implementation.split(":")
    default = " (default)" if s.name == DEFAULT_SAMPLER else ""
    print(f"| `{s.name}`{default} | {s.summary} | `{cls}` in `{module.replace('.', '/')}.py` |")
