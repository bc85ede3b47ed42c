"""exo_ilc_ros: iterative learning control (sgnPDD^2 / PD) for a rehabilitation exoskeleton arm,
as a ROS-free core (:mod:`exo_ilc_ros.core`) under thin ROS 2 nodes (:mod:`exo_ilc_ros.nodes`)."""

__version__ = "0.1.0"
