"""Prints every message of a candump log (argv[1]) as python-can's CanutilsLogReader sees
it: "<timestamp> <channel> <id hex> <ext> <fd> <brs> <esi> <data hex or ->"."""
import sys

import can

for msg in can.CanutilsLogReader(sys.argv[1]):
    print(
        "%.6f %s %x %d %d %d %d %s"
        % (
            msg.timestamp,
            msg.channel,
            msg.arbitration_id,
            msg.is_extended_id,
            msg.is_fd,
            msg.bitrate_switch,
            msg.error_state_indicator,
            msg.data.hex() or "-",
        )
    )
