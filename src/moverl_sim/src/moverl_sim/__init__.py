"""moverl_sim: PyBullet simulator of a robot arm for MoveRL (ROS-free core + rospy node).

Modules: world (world files), urdf (robot description), core (Simulator; imports pybullet),
ros_conversions (ROS messages). Nothing heavy is imported here.
"""
