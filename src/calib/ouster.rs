//! Ouster sensor metadata (the JSON the sensor or the SDK writes) into one validated
//! calibration: the legacy flat form, the FW 1.12/1.13 nested form (where `lidar_data_format`
//! is a string) and the current nested form, with exactly ouster-sdk's defaults where a value
//! is absent (`ouster_core/src/metadata.cpp`, `sensor_info.cpp`).

use crate::model::ouster::PacketFormat;

/// How the sensor stamps its columns (`config_params.timestamp_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TimestampMode {
    /// `TIME_FROM_INTERNAL_OSC`: counts from boot.
    #[default]
    InternalOsc,
    /// `TIME_FROM_SYNC_PULSE_IN`: a sync pulse (and NMEA via the multipurpose IO).
    SyncPulseIn,
    /// `TIME_FROM_PTP_1588`: PTP, TAI.
    Ptp1588,
    /// Anything else the metadata names.
    Unknown,
}

/// IMU UDP profile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ImuProfile {
    /// 48-byte legacy IMU packets.
    #[default]
    Legacy,
    /// ACCEL32_GYRO32_NMEA: header + NMEA block + N measurements + footer.
    Accel32Gyro32Nmea,
    /// Off / unknown.
    Off,
}

/// A validated Ouster calibration: everything the decoder and the frame assembler need.
/// Angles in degrees as the metadata gives them; transforms row-major 4×4, translations in mm.
#[derive(Clone, Debug, PartialEq)]
pub struct OusterInfo {
    /// Product line, e.g. `OS-1-128` (empty when the metadata lacks it).
    pub prod_line: String,
    /// Serial number (0 when absent).
    pub serial: u64,
    /// Firmware revision string, e.g. `v2.3.0`.
    pub firmware: String,
    /// `initialization_id` (0 when absent).
    pub init_id: u32,
    /// Columns per frame (W), from the lidar mode.
    pub columns_per_frame: usize,
    /// Frames per second, from the lidar mode.
    pub fps: u32,
    /// Packet format (profile, columns per packet, pixels per column).
    pub format: PacketFormat,
    /// Column window [first, last] (inclusive; may wrap through 0).
    pub column_window: (usize, usize),
    /// Per-row pixel shift for destaggering (length = pixels per column).
    pub pixel_shift_by_row: Vec<i32>,
    /// Beam altitude angles, degrees (length = pixels per column).
    pub beam_altitude_angles: Vec<f64>,
    /// Beam azimuth angles, degrees (length = pixels per column).
    pub beam_azimuth_angles: Vec<f64>,
    /// `beam_to_lidar_transform`, row-major 4×4 (mm translation).
    pub beam_to_lidar: [f64; 16],
    /// `lidar_to_sensor_transform`, row-major 4×4 (mm translation).
    pub lidar_to_sensor: [f64; 16],
    /// `imu_to_sensor_transform`, row-major 4×4 (mm translation).
    pub imu_to_sensor: [f64; 16],
    /// UDP port of lidar packets (SDK default 7502).
    pub udp_port_lidar: u16,
    /// UDP port of IMU packets (SDK default 7503).
    pub udp_port_imu: u16,
    /// IMU profile.
    pub imu_profile: ImuProfile,
    /// IMU measurements per packet (ACCEL32_GYRO32_NMEA).
    pub imu_measurements_per_packet: usize,
    /// Timestamp mode.
    pub timestamp_mode: TimestampMode,
    /// Which metadata layout the file used: `legacy`, `nested-1.12`, `nested`.
    pub layout: &'static str,
}
