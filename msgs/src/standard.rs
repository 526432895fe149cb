//! Mirrors of the standard ROS 2 types our messages use (`builtin_interfaces/Time`,
//! `std_msgs/Header`, `std_msgs/String`, `std_msgs/Bool`, and `rosgraph_msgs/Clock` for the
//! player's `/clock`), with the DDS type names a ROS 2 peer expects.

use crate::definition::ros_message;

pub mod builtin_interfaces {
    use super::*;

    ros_message! {
        /// A ROS time: seconds and nanoseconds since the epoch (or since the clock's start).
        pub struct Time("builtin_interfaces", "Time", "int32 sec\nuint32 nanosec\n") {
            pub sec: i32,
            pub nanosec: u32,
        }
    }

    impl Time {
        /// From nanoseconds; times before 1970 or after 2038 saturate.
        pub fn from_nanos(nanos: i64) -> Self {
            let sec = nanos.div_euclid(1_000_000_000);
            Time {
                sec: sec.clamp(i32::MIN.into(), i32::MAX.into()) as i32,
                nanosec: nanos.rem_euclid(1_000_000_000) as u32,
            }
        }

        pub fn to_nanos(&self) -> i64 {
            i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
        }

        pub fn from_secs_f64(secs: f64) -> Self {
            Time::from_nanos((secs * 1e9).round() as i64)
        }

        pub fn as_secs_f64(&self) -> f64 {
            self.to_nanos() as f64 * 1e-9
        }
    }
}

pub mod std_msgs {
    pub use super::builtin_interfaces::Time;
    use super::*;

    ros_message! {
        /// Standard metadata for stamped data.
        pub struct Header("std_msgs", "Header", "builtin_interfaces/Time stamp\nstring frame_id\n") {
            pub stamp: Time,
            pub frame_id: String,
        }
    }

    impl Header {
        pub fn at(stamp: Time) -> Self {
            Header {
                stamp,
                frame_id: String::new(),
            }
        }
    }

    ros_message! {
        /// `std_msgs/String`, as QTrobot's speech, emotion and gesture topics take it.
        pub struct StringMsg("std_msgs", "String", "string data\n") {
            pub data: String,
        }
    }

    ros_message! {
        /// `std_msgs/Bool`, as ROS4HRI's latched `/humans/persons/<id>/anonymous` takes it.
        pub struct BoolMsg("std_msgs", "Bool", "bool data\n") {
            pub data: bool,
        }
    }
}

pub mod rosgraph_msgs {
    use super::*;
    use crate::builtin_interfaces::Time;

    ros_message! {
        /// `rosgraph_msgs/Clock` on `/clock`: simulated time, as `bag play --clock` publishes it.
        pub struct Clock("rosgraph_msgs", "Clock", "builtin_interfaces/Time clock\n") {
            pub clock: Time,
        }
    }
}
