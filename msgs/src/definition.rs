//! How a Rust message type describes itself in ROS 2 terms: its package and name, its fields
//! with their ROS types, its constants and its `.msg` text. The mirror test compares this with
//! the parsed `.msg`/`.srv` files; the bag recorder writes the text as the MCAP schema.

use serde::{Serialize, de::DeserializeOwned};

/// What DDS needs of a message: ros2-client's `Message` with the `dds` feature, nothing
/// without it. A supertrait of [`MessageDefinition`], so code generic over messages reaches
/// DDS without naming ros2-client.
#[cfg(feature = "dds")]
pub trait DdsMessage: ros2_client::Message {}
#[cfg(feature = "dds")]
impl<T: ros2_client::Message> DdsMessage for T {}
/// What DDS needs of a message: nothing, as this build has no DDS (`dds` feature off).
#[cfg(not(feature = "dds"))]
pub trait DdsMessage {}
#[cfg(not(feature = "dds"))]
impl<T> DdsMessage for T {}

/// A ROS 2 field type, named as a `.msg` file names it (`float32`, `string[]`,
/// `std_msgs/Header`).
pub trait RosType {
    fn ros_type() -> String;
    /// Appends the message definitions this type needs (itself included, for messages), once each.
    fn collect_dependencies(_out: &mut Vec<Dependency>) {}
}

/// A message definition another definition refers to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dependency {
    /// `pkg/Type`
    pub name: String,
    pub text: &'static str,
}

/// One field of a message, as the Rust mirror declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    pub name: &'static str,
    pub ros_type: String,
}

/// One constant of a message, as the Rust mirror declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Constant {
    pub name: &'static str,
    pub ros_type: String,
    pub value: String,
}

/// A Rust type that mirrors a `.msg` file (or one half of a `.srv` file).
pub trait MessageDefinition:
    Serialize + DeserializeOwned + Clone + std::fmt::Debug + Send + Sync + 'static + DdsMessage
{
    const PACKAGE: &'static str;
    /// `Header`, `OpenFaceFeatures`, or `PredictUser_Request` for a service half.
    const NAME: &'static str;
    /// The text of the `.msg` file (for a service half: its part of the `.srv`).
    fn definition_text() -> &'static str;
    fn fields() -> Vec<Field>;
    fn constants() -> Vec<Constant>;

    /// `pkg/msg/Type`, as rosbag2 names a type.
    fn full_type_name() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }

    /// The definition as rosbag2 stores it in an MCAP schema (`ros2msg` encoding): this
    /// type's text, then each dependency after a line of 80 `=` and `MSG: pkg/Type`.
    fn schema_text() -> String {
        let mut deps = Vec::new();
        for field_deps in Self::field_dependency_collectors() {
            field_deps(&mut deps);
        }
        let mut text = Self::definition_text().trim_end().to_string();
        text.push('\n');
        for dep in deps {
            text.push_str(&"=".repeat(80));
            text.push_str(&format!("\nMSG: {}\n", dep.name));
            text.push_str(dep.text.trim_end());
            text.push('\n');
        }
        text
    }

    /// One collector per field, in order (used for [`Self::schema_text`]).
    fn field_dependency_collectors() -> Vec<fn(&mut Vec<Dependency>)>;
}

pub(crate) fn push_dependency(out: &mut Vec<Dependency>, name: String, text: &'static str) -> bool {
    if out.iter().any(|d| d.name == name) {
        return false;
    }
    out.push(Dependency { name, text });
    true
}

macro_rules! primitive {
    ($($t:ty => $name:literal),* $(,)?) => {$(
        impl RosType for $t {
            fn ros_type() -> String {
                $name.to_string()
            }
        }
    )*};
}

primitive! {
    bool => "bool", i8 => "int8", u8 => "uint8", i16 => "int16", u16 => "uint16",
    i32 => "int32", u32 => "uint32", i64 => "int64", u64 => "uint64",
    f32 => "float32", f64 => "float64", String => "string",
}

impl<T: RosType> RosType for Vec<T> {
    fn ros_type() -> String {
        format!("{}[]", T::ros_type())
    }
    fn collect_dependencies(out: &mut Vec<Dependency>) {
        T::collect_dependencies(out)
    }
}

impl<T: RosType, const N: usize> RosType for [T; N] {
    fn ros_type() -> String {
        format!("{}[{N}]", T::ros_type())
    }
    fn collect_dependencies(out: &mut Vec<Dependency>) {
        T::collect_dependencies(out)
    }
}

/// Declares a message struct together with its ROS description, so the two cannot drift
/// apart without the mirror test noticing.
macro_rules! ros_message {
    (
        $(#[$meta:meta])*
        pub struct $name:ident($pkg:expr, $ros:literal, $text:expr) {
            $( $(#[$fmeta:meta])* pub $field:ident : $ty:ty ),* $(,)?
        }
        $( constants { $( $(#[$cmeta:meta])* $cname:ident : $cty:ty = $cval:expr ),* $(,)? } )?
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $ty, )*
        }

        impl $name {
            $($( $(#[$cmeta])* pub const $cname: $cty = $cval; )*)?
        }

        #[cfg(feature = "dds")]
        impl ros2_client::Message for $name {}

        impl $crate::definition::RosType for $name {
            fn ros_type() -> String {
                format!("{}/{}", $pkg, $ros)
            }
            fn collect_dependencies(out: &mut Vec<$crate::definition::Dependency>) {
                if $crate::definition::push_dependency(out, format!("{}/{}", $pkg, $ros), $text) {
                    $( <$ty as $crate::definition::RosType>::collect_dependencies(out); )*
                }
            }
        }

        impl $crate::definition::MessageDefinition for $name {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $ros;
            fn definition_text() -> &'static str {
                $text
            }
            fn fields() -> Vec<$crate::definition::Field> {
                vec![$( $crate::definition::Field {
                    name: stringify!($field),
                    ros_type: <$ty as $crate::definition::RosType>::ros_type(),
                }, )*]
            }
            fn constants() -> Vec<$crate::definition::Constant> {
                vec![$($( $crate::definition::Constant {
                    name: stringify!($cname),
                    ros_type: <$cty as $crate::definition::RosType>::ros_type(),
                    value: $cval.to_string(),
                }, )*)?]
            }
            fn field_dependency_collectors() -> Vec<fn(&mut Vec<$crate::definition::Dependency>)> {
                vec![$( <$ty as $crate::definition::RosType>::collect_dependencies, )*]
            }
        }
    };
}
pub(crate) use ros_message;
