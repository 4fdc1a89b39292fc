"""Real robots: a world whose physics is ROS 2 robots reached through rmw_zenoh (`plant`),
the robots file that says which robot is which agent (`config`), a simulated fleet that
speaks the same protocol (`fleet`). The protocol itself is swarm.ros2's."""
