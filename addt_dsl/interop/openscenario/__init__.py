"""OpenSCENARIO XML in and out: logical scenarios (ParameterValueDistribution files) in
`distribution.py` (a distribution and its template -> one `.addt` with a sweep) and
`distribution_export.py` (a sweep -> a ParameterValueDistribution); docs/openscenario.md."""
