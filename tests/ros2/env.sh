# The environment rclpy needs from a venv of tests/ros2/requirements.txt (no ROS install):
#   . tests/ros2/env.sh VENV
# Its libraries are in VENV/lib and in the wheels' *.libs folders.
venv=$1
site=$(echo "$venv"/lib/python3*/site-packages)
export AMENT_PREFIX_PATH="$venv" RMW_IMPLEMENTATION=rmw_fastrtps_cpp ROS_DISTRO=jazzy
export PYTHONPATH="$site"
LD_LIBRARY_PATH="$venv/lib"
for d in "$site"/*.libs; do LD_LIBRARY_PATH="$LD_LIBRARY_PATH:$d"; done
export LD_LIBRARY_PATH
