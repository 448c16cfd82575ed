"""What the compiler, the printer and the docs know of each registered element: its keyword,
settings (`ParamSpec`s), docs and compile-time checks, one module per registry. Light by
rule: no module here imports numpy-heavy code, the runtime or the stack (a test compiles
every example and checks `sys.modules`). The implementations subclass these specs
(`addt_dsl/runtime/`, `addt_dsl/stack/`) and load only when a run needs them
(`Registry.implementation`)."""
