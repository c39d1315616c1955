"""The web front end: the status page, live trends, ``/metrics`` and the JSON API.

It runs on aiohttp and prometheus_client (docs/decisions/0032-web-front-end-stack.md); its
``[web]`` table is read by the core (:mod:`gateway.webconfig`), which imports nothing of
the HTTP stack.
"""
