"""moverl_sim: PyBullet simulator of a robot arm for MoveRL (ROS-free core + rospy node).

Modules: world (world files), urdf (robot description), core (Simulator; imports pybullet), lockstep and realtime
(the node's two drivers' decisions), follow (a trajectory controller's rules), camera and camera_schedule (depth
cameras: rendering, and when), ros_conversions (ROS messages); the package README lists them all. Nothing heavy is
imported here.
"""
