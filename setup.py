"""The one compiled part: the steady ring (adapters/link/_ring.c, docs/decisions/0103).

Optional: where no C compiler is, the install goes on without it and the ring runs in
Python (adapters/link/ring.py). Everything else is in pyproject.toml.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension("adapters.link._ring", ["adapters/link/_ring.c"], optional=True),
    ]
)
