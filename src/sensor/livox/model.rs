//! Livox models as data: protocol, laser lines, point rate, ports, and the IMU's published
//! position in the point-cloud frame.

/// Which point-data protocol a model speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Protocol {
    /// 18-byte header, version 5 (Livox-SDK).
    Sdk1,
    /// 36-byte header, version 0 (Livox-SDK2).
    Sdk2,
}

/// A Livox sensor model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LivoxModel {
    /// MID-360 (SDK2, 4 lines, built-in IMU).
    Mid360,
    /// HAP (SDK2, 6 lines, built-in IMU).
    Hap,
    /// Avia (SDK1, 6 lines, built-in IMU).
    Avia,
    /// Horizon (SDK1, 6 lines, built-in IMU).
    Horizon,
    /// Tele-15 (SDK1, 6 lines per livox_ros_driver's table, built-in IMU).
    Tele15,
    /// Mid-40 (SDK1, 1 line, no IMU).
    Mid40,
    /// Mid-70 (SDK1, 1 line, no IMU).
    Mid70,
}

/// Every model, in `--model` order.
pub const ALL_MODELS: [LivoxModel; 7] = [
    LivoxModel::Mid360,
    LivoxModel::Hap,
    LivoxModel::Avia,
    LivoxModel::Horizon,
    LivoxModel::Tele15,
    LivoxModel::Mid40,
    LivoxModel::Mid70,
];

/// First host port of the Livox-SDK (SDK1) data channel: the SDK hands the n-th sensor
/// (from 1) port 56000 + n in its handshake, and that sensor's IMU packets come to the same
/// port (`device_discovery` of Livox-SDK: listen port 55000 + data offset 1000 + n).
pub const SDK1_FIRST_DATA_PORT: u16 = 56_001;

impl LivoxModel {
    /// `--model` spelling.
    pub const fn id(self) -> &'static str {
        match self {
            Self::Mid360 => "mid360",
            Self::Hap => "hap",
            Self::Avia => "avia",
            Self::Horizon => "horizon",
            Self::Tele15 => "tele15",
            Self::Mid40 => "mid40",
            Self::Mid70 => "mid70",
        }
    }

    /// Product name.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Mid360 => "Livox MID-360",
            Self::Hap => "Livox HAP",
            Self::Avia => "Livox Avia",
            Self::Horizon => "Livox Horizon",
            Self::Tele15 => "Livox Tele-15",
            Self::Mid40 => "Livox Mid-40",
            Self::Mid70 => "Livox Mid-70",
        }
    }

    /// The model named `id`.
    pub fn from_id(id: &str) -> Option<Self> {
        ALL_MODELS.into_iter().find(|m| m.id() == id)
    }

    /// Its protocol.
    pub const fn protocol(self) -> Protocol {
        match self {
            Self::Mid360 | Self::Hap => Protocol::Sdk2,
            _ => Protocol::Sdk1,
        }
    }

    /// Laser lines: points of a packet cycle over them, record `i` on line `i % lines`
    /// (livox_ros_driver2 `kLineNumberMid360` = 4, `kLineNumberHAP` = 6; livox_ros_driver's
    /// product table for SDK1: 6 for Tele-15, Horizon and Avia, 1 for Mid-40 and Mid-70).
    pub const fn lines(self) -> u16 {
        match self {
            Self::Mid360 => 4,
            Self::Hap | Self::Avia | Self::Horizon | Self::Tele15 => 6,
            Self::Mid40 | Self::Mid70 => 1,
        }
    }

    /// Points per second (single return): MID-360 200 000 (datasheet), HAP 452 000
    /// (datasheet), SDK1 models from livox_ros_driver's product table.
    pub const fn point_rate(self) -> u32 {
        match self {
            Self::Mid360 => 200_000,
            Self::Hap => 452_000,
            Self::Avia | Self::Horizon | Self::Tele15 => 240_000,
            Self::Mid40 | Self::Mid70 => 100_000,
        }
    }

    /// SDK1 time between consecutive records (firings), ns — livox_ros_driver's
    /// `point_interval` (4167 ns at 240 k/s, 10 000 ns at 100 k/s). SDK2 packets carry their
    /// own interval.
    pub const fn sdk1_point_interval_ns(self) -> u64 {
        match self {
            Self::Mid40 | Self::Mid70 => 10_000,
            _ => 4_167,
        }
    }

    /// Host ports the sensor sends points to by default.
    pub const fn point_port(self) -> u16 {
        match self {
            Self::Mid360 => 56_301,
            Self::Hap => 57_000,
            _ => SDK1_FIRST_DATA_PORT,
        }
    }

    /// Host port of its IMU packets (SDK1: the data port).
    pub const fn imu_port(self) -> Option<u16> {
        match self {
            Self::Mid360 => Some(56_401),
            Self::Hap => Some(58_000),
            Self::Avia | Self::Horizon | Self::Tele15 => Some(SDK1_FIRST_DATA_PORT),
            Self::Mid40 | Self::Mid70 => None,
        }
    }

    /// SDK2: the host port the sensor sends its command answers to by default (MID-360 and HAP
    /// communication protocols: 56101 and 56000); `None` for SDK1 sensors.
    pub const fn sdk2_host_command_port(self) -> Option<u16> {
        match self {
            Self::Mid360 => Some(56_101),
            Self::Hap => Some(56_000),
            _ => None,
        }
    }

    /// SDK2: the sensor's own ports its point and IMU packets leave from (MID-360 56300 /
    /// 56400, HAP 57000 / 58000), which the point and IMU destination commands carry; `None`
    /// for SDK1 sensors.
    pub const fn sdk2_device_data_ports(self) -> Option<(u16, u16)> {
        match self {
            Self::Mid360 => Some((56_300, 56_400)),
            Self::Hap => Some((57_000, 58_000)),
            _ => None,
        }
    }

    /// Whether it has a built-in IMU.
    pub const fn has_imu(self) -> bool {
        self.imu_port().is_some()
    }

    /// The IMU's origin in the point-cloud frame, mm, axes aligned with it, where the maker
    /// publishes it: MID-360 user manual, (11.0, 23.29, −44.12) mm (FAST-LIO's `mid360.yaml`
    /// carries the same as the lidar in the IMU frame, −(…)). Others: `None` (the transform
    /// defaults to identity; override it): the HAP (TX) user manual gives only the point-cloud
    /// origin in its mounting frame, (8, 0, 23) mm, and no IMU position.
    pub const fn imu_position_mm(self) -> Option<[f64; 3]> {
        match self {
            Self::Mid360 => Some([11.0, 23.29, -44.12]),
            _ => None,
        }
    }

    /// Row-major 4 × 4 IMU-to-sensor transform (mm), identity rotation.
    pub fn imu_to_sensor(self) -> [f64; 16] {
        let t = self.imu_position_mm().unwrap_or([0.0; 3]);
        [
            1.0, 0.0, 0.0, t[0], 0.0, 1.0, 0.0, t[1], 0.0, 0.0, 1.0, t[2], 0.0, 0.0, 0.0, 1.0,
        ]
    }

    /// The model an SDK2 datagram to `port` comes from.
    pub fn sdk2_from_port(port: u16) -> Option<Self> {
        match port {
            56_301 | 56_401 => Some(Self::Mid360),
            57_000 | 58_000 => Some(Self::Hap),
            _ => None,
        }
    }
}

/// Standard gravity, m/s² per g (the IMU reports acceleration in g).
pub const STANDARD_GRAVITY: f64 = 9.806_65;
