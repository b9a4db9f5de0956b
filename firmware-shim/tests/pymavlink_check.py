"""Independent decoder for the shim's packets: pymavlink (the reference MAVLink Python
implementation) receives what the shim sends on loopback UDP and checks message ids, CRC,
the SET_ATTITUDE_TARGET fields and the COMMAND_LONG targets.

Usage: python3 pymavlink_check.py N   (binds 127.0.0.1 on a free port, prints it, waits for
N frames, prints one JSON line with what it decoded, exits 0 if every check held)."""

import json
import os
import socket
import sys

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402

want = int(sys.argv[1])
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", 0))
sock.settimeout(20.0)
print(sock.getsockname()[1], flush=True)

mav = mavlink2.MAVLink(None)
mav.robust_parsing = False  # a CRC error raises instead of being skipped
decoded, errors = [], []
while len(decoded) + len(errors) < want:
    data, _ = sock.recvfrom(4096)
    try:
        msgs = mav.parse_buffer(data) or []
    except mavlink2.MAVError as e:
        errors.append(str(e))
        continue
    for m in msgs:
        d = {"id": m.get_msgId(), "name": m.get_type(), "crc_ok": True}
        if m.get_type() == "SET_ATTITUDE_TARGET":
            d.update(type_mask=m.type_mask, thrust=m.thrust, q=list(m.q),
                     target=[m.target_system, m.target_component],
                     rates=[m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate])
        elif m.get_type() == "COMMAND_LONG":
            d.update(command=m.command, target=[m.target_system, m.target_component],
                     params=[m.param1, m.param2, m.param3])
        elif m.get_type() == "HEARTBEAT":
            d.update(type=m.type, autopilot=m.autopilot)
        d["header"] = [m.get_srcSystem(), m.get_srcComponent()]
        decoded.append(d)

ok = not errors
for d in decoded:
    if d["name"] == "SET_ATTITUDE_TARGET":
        ok &= d["type_mask"] == 128 and 0.0 <= d["thrust"] <= 1.0
        ok &= d["q"] == [1.0, 0.0, 0.0, 0.0] and d["target"] == [1, 1]
    if d["name"] == "COMMAND_LONG":
        ok &= d["target"] == [1, 1]
print(json.dumps({"ok": ok, "decoded": decoded, "errors": errors}), flush=True)
sys.exit(0 if ok else 1)
