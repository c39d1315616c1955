"""The Zenoh front end of drive-gateway (key space: :mod:`gateway.zenoh.keys`)."""
