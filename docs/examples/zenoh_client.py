"""A client of drive-gateway's Zenoh keys in Python: a drive's state, a refused-or-accepted
command and a parameter, each a query with the client's source info; a command as a put.
docs/zenoh-keys.md shows this file as it is (``python -m gateway.zenoh.keys``), and
tests/zenoh/test_client_example.py runs it against a gateway. Run against the demo:
``python docs/examples/zenoh_client.py``."""

import itertools
import json

import zenoh  # pip install "eclipse-zenoh>=1.10,<1.11"

ENDPOINT = "tcp/127.0.0.1:7447"  # the gateway's zenoh.listen
PREFIX = "demo"  # the gateway's zenoh.prefix
DRIVE = "cfw11"

conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("connect/endpoints", json.dumps([ENDPOINT]))
conf.insert_json5("listen/endpoints", "[]")
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)

# This client's identity, sent with every put and query: the id of a publisher it declares
# (its session's Zenoh id) and a sequence number. Without it, the gateway takes every such
# client for one and the same "anonymous" client.
me = session.declare_publisher(f"{PREFIX}/drives/{DRIVE}/command")
sequence = itertools.count(1)


def source() -> zenoh.SourceInfo:
    return zenoh.SourceInfo(me.id, next(sequence))


def query(key: str, payload: object = None) -> object:
    """The gateway's one reply, as JSON."""
    options = {"source_info": source(), "timeout": 10.0}
    if payload is not None:
        options["payload"] = json.dumps(payload)
    for reply in session.get(key, **options):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_string())
        return json.loads(reply.err.payload.to_string())  # {"error": "..."}
    raise TimeoutError(f"no answer on {key}: is the gateway running?")


print("state", query(f"{PREFIX}/drives/{DRIVE}/state"))
# a command as a query gets one reply: {"accepted": true} or the reason it was refused;
# {"run": true, "speed_rpm": 900} would start the motor
print("command", query(f"{PREFIX}/drives/{DRIVE}/command", {"run": False}))
print("P100", query(f"{PREFIX}/drives/{DRIVE}/params/100"))
# a command as a put (no reply; a refusal goes to the drive's events key)
me.put(json.dumps({"run": False}), source_info=source())
session.close()
