"""What `ros2 node list`, `ros2 topic info -v TOPIC`, `ros2 param list`, `ros2 param describe`
and `ros2 param set` print, without ros2cli (the Python registry has no ros2cli wheel): the
same rclpy calls and the same output as ros2cli's verbs (`ros2node/verb/list.py`,
`ros2topic/verb/info.py`, `ros2param/verb/list.py`, `describe.py`, `set.py` with one name and
value), from a fresh rclpy node as ros2cli's `--no-daemon` makes one.

    python tests/ros2/ros2cli_view.py node-list
    python tests/ros2/ros2cli_view.py topic-info /qt_robot/speech/say
    python tests/ros2/ros2cli_view.py param-list
    python tests/ros2/ros2cli_view.py param-describe /game_manager language seed
    python tests/ros2/ros2cli_view.py param-set /game_manager language de

Run it in the suite's loopback namespace, in the environment of tests/ros2/env.sh
(docs/ros2_interop.md shows its output for a whole session).
"""

import sys
import time

import rclpy
from rcl_interfaces.msg import Parameter
from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
from rclpy.parameter import get_parameter_value

# ros2param.api's get_parameter_type_string, by rcl_interfaces/msg/ParameterType's codes.
TYPE_NAMES = ['not set', 'boolean', 'integer', 'double', 'string', 'byte array',
              'boolean array', 'integer array', 'double array', 'string array']


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


def call(node, service_type, service, request):
    client = node.create_client(service_type, service)
    if not client.wait_for_service(timeout_sec=5.0):
        return None
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=5.0)
    return future.result()


def param_describe(node, args):
    name, parameters = args[0], args[1:]
    response = call(node, DescribeParameters, f'{name}/describe_parameters',
                    DescribeParameters.Request(names=parameters))
    if response is None:
        return f'no answer from {name}/describe_parameters'
    for d in response.descriptors:
        print('Parameter name:', d.name)
        print('  Type:', TYPE_NAMES[d.type] if d.type < len(TYPE_NAMES) else 'unknown type')
        if d.description:
            print('  Description:', d.description)
        print('  Constraints:')
        if d.read_only:
            print('    Read only: true')
        ranges = list(d.floating_point_range) + list(d.integer_range)
        if ranges:
            print('    Min value:', ranges[0].from_value)
            print('    Max value:', ranges[0].to_value)
            if ranges[0].step:
                print('    Step:', ranges[0].step)
        if d.additional_constraints:
            print('    Additional constraints:', d.additional_constraints)
    return None


def param_set(node, args):
    name, parameter, value = args
    request = SetParameters.Request(parameters=[
        Parameter(name=parameter, value=get_parameter_value(string_value=value))])
    response = call(node, SetParameters, f'{name}/set_parameters', request)
    if response is None:
        return f'no answer from {name}/set_parameters'
    result = response.results[0]
    if result.successful:
        print('Set parameter successful' + (': ' + result.reason if result.reason else ''))
    else:
        print('Setting parameter failed' + (': ' + result.reason if result.reason else ''),
              file=sys.stderr)
    return None


def main():
    verbs = {'node-list': node_list, 'topic-info': topic_info, 'param-list': param_list,
             'param-describe': param_describe, 'param-set': param_set}
    if len(sys.argv) < 2 or sys.argv[1] not in verbs:
        sys.exit(f'usage: {sys.argv[0]} {"|".join(verbs)} [TOPIC | NODE NAME... | NODE NAME VALUE]')
    node = settled_node()
    error = verbs[sys.argv[1]](node, sys.argv[2:])
    node.destroy_node()
    rclpy.try_shutdown()
    if error:
        sys.exit(error)


if __name__ == '__main__':
    main()
