"""Run the ASAM quality checkers (`asam-qc-openscenarioxml`, `asam-qc-opendrive`) in
process on one file and return what they found: (checker id, status, issue texts)."""

from __future__ import annotations

import importlib
import logging

import pytest

INSTALL = "pip install --no-deps -r tests/requirements-opendrive-checker.txt"


def _bundle(package: str):
    try:
        baselib = importlib.import_module("qc_baselib")
        main = importlib.import_module(f"{package}.main")
        constants = importlib.import_module(f"{package}.constants")
    except ImportError as exc:  # the checkers are test requirements outside the extras
        # Skipped, with its reason, like the OpenDRIVE reference test; CI's full run uses
        # `--no-skips`, so a missing checker fails there.
        pytest.skip(f"the ASAM checker {package} is missing ({exc}): {INSTALL}")
    return baselib, main, constants


def check(path, package: str) -> list[tuple[str, str, list[str]]]:
    """Every checker's (id, status, [issue descriptions]) for the file at `path`."""
    baselib, main, constants = _bundle(package)
    config = baselib.Configuration()
    config.set_config_param("InputFile", str(path))
    config.register_checker_bundle(constants.BUNDLE_NAME)
    result = baselib.Result()
    result.register_checker_bundle(name=constants.BUNDLE_NAME, description="", version=constants.BUNDLE_VERSION,
                                   summary="")
    result.set_result_version(version=constants.BUNDLE_VERSION)
    logging.disable(logging.CRITICAL)  # the checkers log every step at INFO
    try:
        main.run_checks(config, result)
    finally:
        logging.disable(logging.NOTSET)
    out = []
    for checker in result.get_checker_results(constants.BUNDLE_NAME):
        issues = [f"{i.level.name}: {i.description}" for i in checker.issues]
        out.append((checker.checker_id, checker.status.name if checker.status else "?", issues))
    return out


def problems(path, package: str) -> list[str]:
    """Errors (and checkers that crashed): what a valid file must not have."""
    found = []
    for checker_id, status, issues in check(path, package):
        if status == "ERROR":
            found.append(f"{checker_id}: checker error")
        found += [f"{checker_id}: {text}" for text in issues if text.startswith("ERROR")]
    return found
