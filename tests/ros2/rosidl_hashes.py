"""RIHS01 type hashes of the suite's interface files as rosidl computes them.

The independent reference for the hashes the node shell puts in each endpoint's USER_DATA:
Jazzy's own code from the `ros-jazzy-rosidl-*` wheels converts every .msg/.srv of the suite's
interface packages to IDL (rosidl_adapter) and hashes it (rosidl_generator_type_description),
with std_msgs, builtin_interfaces and service_msgs from the wheels' share/ folders. Prints
{"pkg/msg/Type": "RIHS01_...", ...} as JSON.

    python tests/ros2/rosidl_hashes.py   (in the ROS 2 environment of tests/ros2/env.sh)
"""

import contextlib
import io
import json
import os
import sys
import tempfile
from pathlib import Path

from rosidl_adapter.msg import convert_msg_to_idl
from rosidl_adapter.srv import convert_srv_to_idl
from rosidl_generator_type_description import generate_type_hash

ROOT = Path(__file__).resolve().parents[2]
# package name -> its folder (holding msg/ and srv/)
PACKAGES = {
    'qt_therapy_msgs': ROOT / 'msgs',
    'hri_msgs': ROOT / 'interfaces' / 'hri_msgs',
    'qt_robot_interface': ROOT / 'interfaces' / 'qt_robot_interface',
    'qtrobot_interfaces': ROOT / 'interfaces' / 'qtrobot_interfaces',
}


def share_dir():
    prefix = os.environ.get('AMENT_PREFIX_PATH', sys.prefix).split(os.pathsep)[0]
    return Path(prefix) / 'share'


def package_hashes(name, folder, out, include_paths):
    idl_tuples = []
    for kind, convert in (('msg', convert_msg_to_idl), ('srv', convert_srv_to_idl)):
        for f in sorted((folder / kind).glob(f'*.{kind}')):
            idl = convert(folder, name, f.relative_to(folder), out / 'idl' / kind)
            idl_tuples.append(f'{out / "idl"}:{Path(kind) / idl.name}')
    args = {
        'package_name': name,
        'output_dir': str(out / 'json'),
        'idl_tuples': idl_tuples,
        'include_paths': include_paths,
    }
    args_file = out / 'args.json'
    args_file.write_text(json.dumps(args))
    hashes = {}
    for path in generate_type_hash(str(args_file)):
        for entry in json.loads(Path(path).read_text())['type_hashes']:
            hashes[entry['type_name']] = entry['hash_string']
    return hashes


def suite_hashes():
    """{type name: RIHS01 hash} of every type of the suite's interface packages (their
    services' halves and event messages too), as rosidl computes them."""
    share = share_dir()
    include_paths = [f'{p}:{share / p}' for p in ('std_msgs', 'builtin_interfaces', 'service_msgs')]
    hashes = {}
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        for name, folder in PACKAGES.items():
            out = Path(tmp) / name
            out.mkdir()
            hashes.update(package_hashes(name, folder, out, include_paths))
            include_paths.append(f'{name}:{out / "json"}')
    return hashes


def main():
    json.dump(dict(sorted(suite_hashes().items())), sys.stdout, indent=1)
    print()


if __name__ == '__main__':
    main()
