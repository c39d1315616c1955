"""Stateful model checks of the safety rules, one per device kind (docs/safety.md)."""
