"""ROS 2 without ROS: the rmw_zenoh protocol spoken over a zenoh session (message types and
their hashes, topic keys, liveliness tokens, attachments, CDR payloads, a node)."""
