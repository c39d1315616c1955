"""Fixtures of the security tests: the Modbus tests reuse the Modbus front end's
in-process gateway (tests/modbus/conftest.py), so they test the same set-up."""

from tests.modbus.conftest import start_gateway

__all__ = ["start_gateway"]
