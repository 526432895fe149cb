"""What `ros2 node list`, `ros2 topic info -v TOPIC` and `ros2 param list` print, without
ros2cli (the Python registry has no ros2cli wheel): the same rclpy calls and the same output
as ros2cli's jazzy verbs (`ros2node/verb/list.py`, `ros2topic/verb/info.py`,
`ros2param/verb/list.py`), from a fresh rclpy node as ros2cli's `--no-daemon` makes one.

    python tests/ros2/ros2cli_view.py node-list
    python tests/ros2/ros2cli_view.py topic-info /qt_robot/speech/say
    python tests/ros2/ros2cli_view.py param-list

Run it in the suite's loopback namespace, in the environment of tests/ros2/env.sh
(docs/ros2_interop.md shows its output for a whole session).
"""

import sys
import time

import rclpy
from rcl_interfaces.srv import ListParameters


def settled_node():
    rclpy.init()
    node = rclpy.create_node('_ros2cli_view')
    # ros2cli's DirectNode spins for discovery before it asks; two seconds is plenty on one
    # host.
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    return node


def full_names(node):
    return sorted(
        (ns.rstrip('/') + '/' + name) for name, ns in node.get_node_names_and_namespaces()
        if not name.startswith('_'))


def node_list(node, _args):
    print(*full_names(node), sep='\n')


def topic_info(node, args):
    topic = args[0]
    types = dict(node.get_topic_names_and_types())
    if topic not in types:
        return f"Unknown topic '{topic}'"
    line_end = '\n\n'
    t = types[topic]
    print('Type: %s' % (t[0] if len(t) == 1 else t), end=line_end)
    print('Publisher count: %d' % node.count_publishers(topic), end=line_end)
    for info in node.get_publishers_info_by_topic(topic):
        print(info, end=line_end)
    print('Subscription count: %d' % node.count_subscribers(topic), end=line_end)
    for info in node.get_subscriptions_info_by_topic(topic):
        print(info, end=line_end)
    return None


def param_list(node, _args):
    for name in full_names(node):
        client = node.create_client(ListParameters, f'{name}/list_parameters')
        if not client.wait_for_service(timeout_sec=5.0):
            print(f'Wait for service timed out waiting for parameter services for node {name}')
            continue
        future = client.call_async(ListParameters.Request())
        rclpy.spin_until_future_complete(node, future, timeout_sec=5.0)
        if future.result() is None:
            print(f"Exception while calling service of node '{name}': no answer",
                  file=sys.stderr)
            continue
        names = sorted(future.result().result.names)
        if names:
            print(f'{name}:')
        for n in names:
            print(f'  {n}')
    return None


def main():
    verbs = {'node-list': node_list, 'topic-info': topic_info, 'param-list': param_list}
    if len(sys.argv) < 2 or sys.argv[1] not in verbs:
        sys.exit(f'usage: {sys.argv[0]} {"|".join(verbs)} [TOPIC]')
    node = settled_node()
    error = verbs[sys.argv[1]](node, sys.argv[2:])
    node.destroy_node()
    rclpy.try_shutdown()
    if error:
        sys.exit(error)


if __name__ == '__main__':
    main()
