//! The shared shell of every node in the suite, and the only crate that touches ros2-client.
//! A node's code is written against [`Bus`] (`bus`): typed publishers and validated
//! subscriptions on the suite's topics, services, a clock and a stop signal. [`NodeShell`] is
//! the bus over DDS: it reads `params/<node>.yaml` (ROS 2 parameter-file form), joins the ROS 2
//! graph with the QoS each topic class needs, logs to stderr and `/rosout`, publishes a
//! heartbeat, exits cleanly on SIGINT/SIGTERM, and exits non-zero if RustDDS's threads end (so
//! that it is started again). [`in_process::InProcessBus`] runs the same nodes in one process
//! on a virtual clock, for the cross-node tests. Node cores stay sans-IO: a node's run loop
//! only moves messages between its bus and its core.
//!
//! One module per job: `options` (command line, parameter files), `environment` (domain,
//! localhost-only), `qos`, `names`, `participant` (start-up), `publish`, `subscribe`,
//! `services`, `tap`, `heartbeat`, `shutdown` (signals, clean stop), `security`, `dds_watch`,
//! `dds` (NodeShell as a Bus), `in_process`, `clock`, `drops`, `logging`, `params` (the
//! parameter file), `parameters` and `parameter_services` (the parameters as ROS 2 tools see
//! and set them), `graph`
//! (which node owns an endpoint), `foreign` (topics not the suite's), `type_hashes` (the type
//! hash each endpoint announces); and `instance_lock`, the `instance_lock` library's, which
//! offline tools use too.

pub mod bus;
pub mod clock;
mod dds;
pub mod dds_watch;
pub mod drops;
mod environment;
pub mod foreign;
pub mod graph;
pub mod heartbeat;
pub mod in_process;
pub mod logging;
mod names;
mod options;
mod parameter_services;
pub mod parameters;
pub mod params;
mod participant;
mod publish;
mod qos;
pub mod security;
mod services;
mod shutdown;
mod subscribe;
pub mod tap;
pub mod type_hashes;

// `#[derive(DescribedParameters)]` names `::node_shell`, here too.
extern crate self as node_shell;

pub use bus::{Bus, CallError, Outbox, ServiceCall, ServiceClient};
pub use clock::Clock;
pub use environment::{domain_id_from_env, localhost_only_from_env};
/// One process per state directory (`libs/instance_lock`), which the nodes' shells take.
pub use instance_lock;
pub use names::ros_name;
pub use options::{INSTALLED_PARAMS_DIR, NoParameters, ShellOptions};
pub use participant::NodeShell;
pub use qos::{qos_profile, service_qos};

use qt_therapy_msgs::std_msgs::Header;

/// Wall-clock time in nanoseconds since the epoch, for tools and tests; a node reads its
/// bus's clock instead ([`Bus::clock`]), which is virtual when the suite runs in process.
pub fn now_nanos() -> i64 {
    clock::wall_nanos()
}

/// A header stamped now by the wall clock (see [`now_nanos`]).
pub fn header_now() -> Header {
    Clock::wall().header_now()
}
