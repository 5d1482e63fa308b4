"""ROS 2 over Zenoh as rmw_zenoh speaks it, without ROS installed (docs/ros2.md).

A library below the runtime, like `hapticop.network`: key expressions, type hashes, the per-sample
attachment, liveliness tokens and QoS strings (`names.py`, `attachment.py`), and the CDR messages that
carry a port's array (`messages.py`). It imports no Zenoh: the ROS 2 bridge reaches Zenoh through
`hapticop.network.transport`, like the two-host bridge, in a process of its own.
"""
