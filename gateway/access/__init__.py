"""Who may do what: roles, identities and their secrets, web sessions, the audit trail.

Part of the core (every front end maps its own identities to the roles of
:mod:`gateway.access.roles`, and records its decisions on :mod:`gateway.access.audit`)."""
