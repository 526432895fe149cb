"""A real ROS 2 Jazzy peer (rclpy on rmw_fastrtps_cpp) that joins a whole session of the suite
and looks at it as `ros2 node list`, `ros2 topic info -v`, `ros2 topic echo` and rqt do.

tests/ros2_graph.rs starts it in the session's loopback namespace, with the environment of
tests/ros2/env.sh. Two phases:

  peer.py session --report R.json --expect-nodes a,b,... --dump-dir D [--graph-after S]
      up before the suite: publishes two topics of its own for the recorder
      (/ros2_peer/chatter, std_msgs/String; /ros2_peer/count, std_msgs/Int32, a type the
      suite does not know), counts the robot's utterances, reads /rosout as rqt_console does; once every
      expected node is listed (or --graph-after seconds have passed) it checks the graph: each
      node listed, every endpoint of the suite's topics and services attributed to a node, each
      endpoint's type hash equal to rosidl's. Then the parameters, as `ros2 param` does them
      (rclpy's AsyncParameterClient): each node's listed, got, described; one set taken
      (seen on /parameter_events), others refused with their reasons; each node's dumped into
      D/<node>.yaml as `ros2 param dump` writes it, for the Rust test to load back. It writes
      its report at SIGINT/SIGTERM.
  peer.py play --report R.json --seconds S
      counts /clock (rosgraph_msgs/Clock) while `bag play --clock` plays.

Each check is {"check", "ok", "detail"} in the report; the Rust test asserts them.
"""

import argparse
import json
import signal
import sys
import time
from pathlib import Path

import rclpy
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos import qos_profile_parameter_events
from rcl_interfaces.msg import Log, ParameterEvent, ParameterType
import yaml
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Int32, String

sys.path.insert(0, str(Path(__file__).resolve().parent))
import rosidl_hashes  # noqa: E402

SPEECH = '/qt_robot/speech/say'
FOREIGN = '/ros2_peer/chatter'
# A type the suite does not know: the recorder must ask this node for its definition.
FOREIGN_UNKNOWN_TYPE = '/ros2_peer/count'
# What rclpy itself announces (its own node's endpoints and the ROS 2 builtins) is not the
# suite's: the checks look at the endpoints of the suite's nodes.
ROS_BUILTIN_TOPICS = {'/rosout', '/parameter_events'}


def ros_type_name(type_name):
    """`pkg/msg/Type`, also for a service's request and reply topics, which rcl names by their
    DDS type (`pkg::srv::dds_::Type_Request_`)."""
    if '::dds_::' in type_name:
        return type_name.replace('::dds_::', '::').replace('::', '/').rstrip('_')
    return type_name


def hash_text(type_hash):
    """rclpy's TypeHash as `ros2 topic info -v` prints it."""
    if type_hash.version != 1:
        return 'INVALID'
    return 'RIHS01_' + bytes(type_hash.value).hex()


class Report:
    def __init__(self, path):
        self.path = path
        self.checks = []
        self.facts = {}

    def check(self, name, ok, detail=''):
        self.checks.append({'check': name, 'ok': bool(ok), 'detail': detail})
        print(f"[ros2_peer] {'ok  ' if ok else 'FAIL'} {name}: {detail}", flush=True)

    def write(self):
        Path(self.path).write_text(json.dumps({'checks': self.checks, 'facts': self.facts},
                                              indent=1))


def endpoint_rows(node, suite_nodes):
    """Every endpoint on the graph as (kind, topic, node, type, hash): topics by rclpy's own
    calls, services through their request and reply topics (no_mangle, as rqt_graph reads
    them)."""
    rows = []
    for topic, _types in node.get_topic_names_and_types():
        for kind, infos in (('publisher', node.get_publishers_info_by_topic(topic)),
                            ('subscription', node.get_subscriptions_info_by_topic(topic))):
            for i in infos:
                rows.append((kind, topic, i.node_name, i.topic_type, hash_text(i.topic_type_hash)))
    services = set()
    for name in suite_nodes:
        try:
            by_node = node.get_service_names_and_types_by_node(name, '/')
        except Exception as e:  # rclpy's NodeNameNonExistentError, not exported
            if 'nonexistent node' not in str(e):
                raise
            # rcl does not know the node: the node list check reports it.
            continue
        for service, _types in by_node:
            services.add(service)
    for service in sorted(services):
        for dds_topic in (f'rq{service}Request', f'rr{service}Reply'):
            for kind, infos in (
                    ('publisher', node.get_publishers_info_by_topic(dds_topic, no_mangle=True)),
                    ('subscription',
                     node.get_subscriptions_info_by_topic(dds_topic, no_mangle=True))):
                for i in infos:
                    rows.append((kind, dds_topic, i.node_name, i.topic_type,
                                 hash_text(i.topic_type_hash)))
    return rows


def check_graph(node, report, expected_nodes, reference):
    listed = sorted(n for n, ns in node.get_node_names_and_namespaces() if ns == '/')
    missing = sorted(set(expected_nodes) - set(listed))
    report.facts['node_list'] = listed
    report.check('every node of the suite is listed', not missing,
                 f'listed {listed}, missing {missing}')
    rows = endpoint_rows(node, expected_nodes)
    report.facts['endpoints'] = [list(r) for r in rows]
    ours = set(expected_nodes)
    unattributed = sorted({(k, t, n) for k, t, n, _ty, _h in rows
                           if n in ('_NODE_NAME_UNKNOWN_', '_CREATED_BY_BARE_DDS_APP_')})
    report.check('every endpoint is attributed to its node', not unattributed,
                 f'{len(rows)} endpoints; unattributed: {unattributed[:12]}')
    wrong = []
    checked = 0
    for kind, topic, owner, type_name, type_hash in rows:
        if owner not in ours:
            continue
        expected = reference.get(ros_type_name(type_name))
        if expected is None:
            wrong.append((kind, topic, owner, type_name, type_hash, 'no rosidl reference'))
            continue
        checked += 1
        if type_hash != expected:
            wrong.append((kind, topic, owner, type_name, type_hash))
    report.check("every endpoint's type hash is rosidl's", checked > 0 and not wrong,
                 f'{checked} endpoints of the suite checked; wrong: {wrong[:8]}')


def call(node, future, timeout=10.0):
    """The answer of a service call, or None after `timeout` s (spinning meanwhile)."""
    rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
    return future.result() if future.done() else None


def dump(node, client, name, dump_dir):
    """`ros2 param dump NAME` (ros2cli's jazzy ros2param/verb/dump.py): list, get every
    name, nest the dotted ones, yaml.dump with default_flow_style=False."""
    listed = call(node, client.list_parameters())
    if listed is None:
        return None
    names = sorted(listed.result.names)
    got = call(node, client.get_parameters(names))
    if got is None:
        return None
    params = {}
    for key, value in zip(names, got.values):
        d = params
        parts = key.split('.')
        for part in parts[:-1]:
            d = d.setdefault(part, {})
        d[parts[-1]] = parameter_value_to_python(value)
    text = yaml.dump({f'/{name}': {'ros__parameters': params}}, default_flow_style=False)
    Path(dump_dir, f'{name}.yaml').write_text(text)
    return names


def check_parameters(node, report, expected_nodes, events, dump_dir):
    """What `ros2 param list/get/describe/set/dump` do, against every node of the suite."""
    Path(dump_dir).mkdir(parents=True, exist_ok=True)
    clients = {name: AsyncParameterClient(node, f'/{name}') for name in expected_nodes}
    listed = {}
    for name, client in clients.items():
        if client.wait_for_services(timeout_sec=10.0):
            listed[name] = dump(node, client, name, dump_dir)
        else:
            listed[name] = None
    report.facts['parameters'] = listed
    unanswered = sorted(n for n, names in listed.items() if names is None)
    report.check('every node answers list_parameters and get_parameters', not unanswered,
                 f'unanswered: {unanswered}')
    # Every node lists its own parameters beside use_sim_time (the console has none).
    bare = sorted(n for n, names in listed.items()
                  if names is not None and n != 'therapist_console' and
                  set(names) <= {'use_sim_time'})
    report.check("every node lists its own parameters", not bare,
                 f'only use_sim_time: {bare}; game_manager: {listed.get("game_manager")}')
    gm = clients['game_manager']
    ec = clients['engagement_classifier']

    got = call(node, gm.get_parameters(['language', 'seed', 'watched_nodes']))
    values = [parameter_value_to_python(v) for v in got.values] if got else None
    # seed: tests/ros2_graph.rs launches with seed:=7 (`--param seed:=7`, over the
    # parameter file's 42).
    report.check('get_parameters gives the values the node runs with', values is not None and
                 values[0] == 'en' and values[1] == 7 and 'tablet_bridge' in values[2],
                 f'game_manager language, seed, watched_nodes: {values}')
    types = call(node, gm.get_parameter_types(['language', 'watched_nodes', 'time_scale']))
    types = list(types.types) if types else None
    report.check('get_parameter_types gives the types', types == [
        ParameterType.PARAMETER_STRING, ParameterType.PARAMETER_STRING_ARRAY,
        ParameterType.PARAMETER_DOUBLE], f'{types}')

    described = call(node, gm.describe_parameters(['language', 'seed']))
    d = described.descriptors if described else []
    report.facts['described'] = [
        {'name': x.name, 'type': x.type, 'description': x.description,
         'read_only': x.read_only, 'additional_constraints': x.additional_constraints}
        for x in d]
    report.check('describe_parameters gives each description and whether it is read-only',
                 len(d) == 2 and d[0].description.startswith('Language of the robot') and
                 not d[0].read_only and d[1].read_only and d[1].description != '',
                 f'{report.facts["described"]}')
    unknown = call(node, gm.describe_parameters(['no_such_parameter']))
    report.check('describe of a name not declared is empty (as rclcpp)',
                 unknown is not None and len(unknown.descriptors) == 0,
                 f'{unknown.descriptors if unknown else "no answer"}')

    # One change taken: the classifier's min_confidence, applied from its next frame.
    set_ok = call(node, ec.set_parameters([Parameter('min_confidence', value=0.7)]))
    ok = set_ok.results[0] if set_ok else None
    report.check('set_parameters of a writable parameter is taken',
                 ok is not None and ok.successful, f'{ok}')
    end = time.monotonic() + 5.0
    seen = []
    while time.monotonic() < end and not seen:
        rclpy.spin_once(node, timeout_sec=0.1)
        seen = [e for e in events if e.node == '/engagement_classifier' and any(
            p.name == 'min_confidence' and p.value.double_value == 0.7
            for p in e.changed_parameters)]
    report.check('the change is on /parameter_events', bool(seen),
                 f'{len(events)} events: {[(e.node, [p.name for p in e.changed_parameters]) for e in events]}')
    got = call(node, ec.get_parameters(['min_confidence']))
    value = parameter_value_to_python(got.values[0]) if got and got.values else None
    report.check('get_parameters gives the new value', value == 0.7, f'{value}')

    # Refused: read-only (the node shell, in rclcpp's words), not declared, of the wrong type,
    # all or nothing (atomically), and a value the game manager's core refuses.
    refusals = {}
    for client, who, params in [
            (gm, 'read-only', [Parameter('seed', value=1)]),
            (gm, 'not declared', [Parameter('no_such_parameter', value=1)]),
            (ec, 'wrong type', [Parameter('min_confidence', value='high')]),
            (gm, 'refused by the core', [Parameter('proposal_countdown_s', value=-1.0)])]:
        r = call(node, client.set_parameters(params))
        refusals[who] = (r.results[0].successful, r.results[0].reason) if r else None
    atomic = call(node, ec.set_parameters_atomically(
        [Parameter('min_confidence', value=0.6), Parameter('smoothing_alpha', value=0.5)]))
    refusals['atomically, one read-only'] = (
        (atomic.result.successful, atomic.result.reason) if atomic else None)
    report.facts['refusals'] = refusals
    want = {
        'read-only': "parameter 'seed' cannot be set because it is read-only",
        'not declared': "parameter 'no_such_parameter' cannot be set because it was not declared",
        'wrong type': 'Wrong parameter type, parameter {min_confidence} is of type {double}, '
                      'setting it to {string} is not allowed.',
        'atomically, one read-only':
            "parameter 'smoothing_alpha' cannot be set because it is read-only",
    }
    wrong = {k: v for k, v in refusals.items()
             if v is None or v[0] or (k in want and v[1] != want[k]) or
             (k == 'refused by the core' and 'proposal_countdown_s' not in v[1])}
    report.check('refused sets say why, as rclcpp does', not wrong, f'{refusals}')
    got = call(node, ec.get_parameters(['min_confidence']))
    value = parameter_value_to_python(got.values[0]) if got and got.values else None
    report.check('a refused atomic set changes nothing', value == 0.7, f'{value}')
    # The dump after the change holds it (the Rust test loads every dump back).
    dump(node, ec, 'engagement_classifier', dump_dir)


def reference_hashes():
    """rosidl's hashes of the suite's interfaces and of the ROS 2 types its builtin
    endpoints carry (from the wheels' share/ folders)."""
    hashes = rosidl_hashes.suite_hashes()
    share = rosidl_hashes.share_dir()
    for json_file in share.glob('*/*/*.json'):
        try:
            for entry in json.loads(json_file.read_text()).get('type_hashes', []):
                hashes.setdefault(entry['type_name'], entry['hash_string'])
        except (ValueError, AttributeError):
            continue
    return hashes


def session(args):
    report = Report(args.report)
    expected_nodes = [n for n in args.expect_nodes.split(',') if n]
    reference = reference_hashes()
    rclpy.init()
    node = rclpy.create_node('ros2_peer')
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
    utterances = []
    node.create_subscription(String, SPEECH, lambda m: utterances.append(m.data), reliable)
    # As rqt_console: every record, the ones logged before it joined too (rosout is
    # transient-local in ROS 2).
    rosout_qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL,
                            history=HistoryPolicy.KEEP_LAST)
    rosout = {}
    node.create_subscription(
        Log, '/rosout',
        lambda m: rosout.setdefault(m.name, set()).add(m.level), rosout_qos)
    events = []
    node.create_subscription(ParameterEvent, '/parameter_events', events.append,
                             qos_profile_parameter_events)
    chatter = node.create_publisher(String, FOREIGN, reliable)
    counter = node.create_publisher(Int32, FOREIGN_UNKNOWN_TYPE, reliable)
    sent = [0]

    def chat():
        sent[0] += 1
        chatter.publish(String(data=f'hello from rclpy {sent[0]}'))
        counter.publish(Int32(data=sent[0]))

    node.create_timer(0.5, chat)
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
    signal.signal(signal.SIGINT, lambda *_: stop.__setitem__(0, True))
    started = time.monotonic()
    graph_checked = False
    last_listed = [set()]
    while not stop[0]:
        rclpy.spin_once(node, timeout_sec=0.2)
        if graph_checked:
            continue
        listed = {n for n, _ in node.get_node_names_and_namespaces()}
        waited = time.monotonic() - started
        if listed != last_listed[0]:
            print(f'[ros2_peer] {waited:5.1f} s: {len(listed)} nodes listed: {sorted(listed)}',
                  flush=True)
            last_listed[0] = listed
        if set(expected_nodes) <= listed and waited > args.settle or waited > args.graph_after:
            # Let discovery of every endpoint settle once the nodes are there.
            end = time.monotonic() + 2.0
            while time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.2)
            check_graph(node, report, expected_nodes, reference)
            check_parameters(node, report, expected_nodes, events, args.dump_dir)
            graph_checked = True
            report.write()
    if not graph_checked:
        report.check('every node of the suite is listed', False, 'the session ended first')
    report.facts['utterances'] = utterances
    report.facts['rosout_levels'] = {k: sorted(v) for k, v in rosout.items()}
    report.facts['foreign_sent'] = sent[0]
    report.write()
    node.destroy_node()
    rclpy.try_shutdown()


def play(args):
    report = Report(args.report)
    rclpy.init()
    node = rclpy.create_node('ros2_clock_peer')
    stamps = []
    # As a node with use_sim_time subscribes (rclpy's TimeSource: best effort, keep last 1).
    clock_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                           durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
    node.create_subscription(Clock, '/clock', lambda m: stamps.append(
        m.clock.sec * 1_000_000_000 + m.clock.nanosec), clock_qos)
    end = time.monotonic() + args.seconds
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
    while time.monotonic() < end and not stop[0]:
        rclpy.spin_once(node, timeout_sec=0.2)
    report.facts['clock_messages'] = len(stamps)
    increasing = all(b >= a for a, b in zip(stamps, stamps[1:]))
    report.check('bag play --clock publishes /clock (rosgraph_msgs/Clock)',
                 len(stamps) > 0 and increasing,
                 f'{len(stamps)} /clock messages, non-decreasing: {increasing}')
    report.write()
    node.destroy_node()
    rclpy.try_shutdown()


def main():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest='phase', required=True)
    s = sub.add_parser('session')
    s.add_argument('--report', required=True)
    s.add_argument('--expect-nodes', required=True)
    s.add_argument('--dump-dir', required=True)
    s.add_argument('--settle', type=float, default=3.0)
    s.add_argument('--graph-after', type=float, default=16.0)
    p = sub.add_parser('play')
    p.add_argument('--report', required=True)
    p.add_argument('--seconds', type=float, default=10.0)
    args = parser.parse_args()
    {'session': session, 'play': play}[args.phase](args)


if __name__ == '__main__':
    main()
