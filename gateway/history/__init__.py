"""The gateway's own history: every drive's readings and every event in SQLite on the box
(docs/decisions/0083-history-store.md)."""
