"""The web front end: the status page, live trends, ``/metrics`` and the JSON API.

``gateway.web.settings`` (the ``[web]`` table) imports nothing of the HTTP stack; the rest
of the package runs on aiohttp and prometheus_client (docs/decisions.md, "Web status page").
"""
