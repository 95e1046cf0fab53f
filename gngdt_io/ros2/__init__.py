"""ROS 2 over zenoh without a ROS installation: rmw_zenoh's wire format (`wire`: key
expressions, liveliness tokens, QoS strings, attachments, GIDs), ROS 2 messages as CDR through
rosbags (`messages`, `markers`) and a node on a zenoh session (`node`). `gngdt ros2`
(`gngdt.services.ros2`) bridges gngdt's topics and a ROS 2 graph with them."""
