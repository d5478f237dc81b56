"""Reads lines "<timestamp> <id hex> <ext 0/1> <fd 0/1> <brs 0/1> <esi 0/1> <data hex>" on
stdin and prints, per line, python-can's own udp_multicast datagram for that message (hex),
then a tab, then the fields python-can decodes from the datagram robobus made for it
(given as an eighth column, hex)."""
import sys

import can
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

for line in sys.stdin:
    ts, ident, ext, fd, brs, esi, data, ours = line.split()
    msg = can.Message(
        timestamp=float(ts),
        arbitration_id=int(ident, 16),
        is_extended_id=ext == "1",
        is_fd=fd == "1",
        bitrate_switch=brs == "1",
        error_state_indicator=esi == "1",
        data=bytes.fromhex(data if data != "-" else ""),
        check=True,
    )
    back = unpack_message(bytes.fromhex(ours), check=True)
    fields = "%r %x %d %d %d %d %s" % (
        back.timestamp,
        back.arbitration_id,
        back.is_extended_id,
        back.is_fd,
        back.bitrate_switch,
        back.error_state_indicator,
        back.data.hex() or "-",
    )
    print(pack_message(msg).hex() + "\t" + fields, flush=True)
