"""The wire contract, one home: topic and service names, types and QoS (:mod:`.topics`,
:mod:`.qos`), the trial protocol's key-values (:mod:`.protocol`) and the CDR fast paths of the
control loop's messages (:mod:`.cdr`). The nodes, the recorder, the bag reader and ``exo-ilc
run``'s monitor all encode and parse through it. ROS-free."""
