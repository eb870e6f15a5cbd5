//! Hesai's TCP control protocol (PTC, port 9347): the commands ringscan needs, "get angle
//! correction" (0x05), which returns the file a Hesai sensor is calibrated with (the CSV, or the
//! AT128's or ATX's `.dat`), so that a live sensor can be decoded without a file on disk, and
//! the ATX's "get firetimes" (0xA9, HesaiLidar_SDK_2.0's `kPTCGetLidarFiretimes`), its firetime
//! correction in the binary form.
//!
//! Framing (Hesai user manuals, "TCP API"; the same as nebula's `hesai_hw_interface`):
//! request = `47 74`, command, one zero byte, payload length (u32 big-endian), payload;
//! response = `47 74`, command, return code (0 = success), payload length (u32 big-endian),
//! payload. This is the I/O edge: the library only parses what comes back
//! ([`crate::sensor::hesai::family::parse_hesai_calibration`]).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

/// The PTC port.
pub const PTC_PORT: u16 = 9347;
/// "Get angle correction".
pub const GET_ANGLE_CORRECTION: u8 = 0x05;
/// "Get firetimes" (the ATX's firetime correction).
pub const GET_FIRETIMES: u8 = 0xA9;
/// Largest response accepted (real correction files are < 100 kB).
const MAX_RESPONSE: usize = 4 << 20;

/// Sends one PTC command and returns the response payload, all of it within `timeout`: a
/// sensor that answers a byte at a time cannot hold the caller (`listen --hesai-ptc` waits on
/// it before listening) longer than that.
pub fn command(
    addr: SocketAddr,
    cmd: u8,
    payload: &[u8],
    timeout: Duration,
) -> Result<Vec<u8>, String> {
    let deadline = Instant::now() + timeout;
    let mut s = TcpStream::connect_timeout(&addr, timeout).map_err(|e| format!("{addr}: {e}"))?;
    s.set_write_timeout(Some(timeout))
        .map_err(|e| e.to_string())?;
    let mut req = vec![0x47, 0x74, cmd, 0];
    req.extend_from_slice(&(payload.len() as u32).to_be_bytes());
    req.extend_from_slice(payload);
    s.write_all(&req)
        .map_err(|e| format!("{addr}: sending the PTC request: {e}"))?;
    let mut head = [0u8; 8];
    read_by(&mut s, &mut head, deadline).map_err(|e| {
        format!(
            "{addr}: reading the PTC response header: {}",
            late(e, timeout)
        )
    })?;
    if head[..2] != [0x47, 0x74] || head[2] != cmd {
        return Err(format!(
            "{addr}: not a PTC response to command {cmd:#04x}: header {:02x?}",
            &head[..4]
        ));
    }
    if head[3] != 0 {
        return Err(format!(
            "{addr}: the sensor answered command {cmd:#04x} with error code {:#04x}",
            head[3]
        ));
    }
    let len = u32::from_be_bytes([head[4], head[5], head[6], head[7]]) as usize;
    if len > MAX_RESPONSE {
        return Err(format!(
            "{addr}: PTC response of {len} bytes refused (over {MAX_RESPONSE})"
        ));
    }
    let mut body = vec![0u8; len];
    read_by(&mut s, &mut body, deadline).map_err(|e| {
        format!(
            "{addr}: reading {len} bytes of PTC payload: {}",
            late(e, timeout)
        )
    })?;
    Ok(body)
}

/// Fills `buf` from `s` before `deadline` (each read waits only for the time left).
fn read_by(s: &mut TcpStream, buf: &mut [u8], deadline: Instant) -> std::io::Result<()> {
    use std::io::ErrorKind;
    let mut got = 0;
    while got < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(ErrorKind::TimedOut.into());
        }
        s.set_read_timeout(Some(left))?;
        match s.read(&mut buf[got..]) {
            Ok(0) => return Err(ErrorKind::UnexpectedEof.into()),
            Ok(n) => got += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// A read error, said as the time limit where it was one.
fn late(e: std::io::Error, timeout: Duration) -> String {
    use std::io::ErrorKind;
    match e.kind() {
        ErrorKind::TimedOut | ErrorKind::WouldBlock => {
            format!("no complete response within {timeout:?}")
        }
        ErrorKind::UnexpectedEof => "the sensor closed the connection".to_string(),
        _ => e.to_string(),
    }
}

/// The angle-correction file of the Hesai sensor at `addr` (its PTC port), checked to be one
/// ringscan reads.
pub fn fetch_angle_correction(addr: SocketAddr, timeout: Duration) -> Result<Vec<u8>, String> {
    let bytes = command(addr, GET_ANGLE_CORRECTION, &[], timeout)?;
    match crate::sensor::hesai::family::parse_hesai_calibration(&bytes) {
        Some(Ok(_)) => Ok(bytes),
        Some(Err(e)) => Err(format!("{addr}: the sensor's angle correction: {e}")),
        None => Err(format!(
            "{addr}: the sensor's angle correction ({} bytes) is neither a Hesai CSV nor an AT128 or ATX .dat",
            bytes.len()
        )),
    }
}

/// The firetime correction of the ATX at `addr` (its PTC port), read from the binary form the
/// sensor serves.
pub fn fetch_atx_firetimes(
    addr: SocketAddr,
    timeout: Duration,
) -> Result<crate::sensor::hesai::atx::AtxFiretimes, String> {
    let bytes = command(addr, GET_FIRETIMES, &[], timeout)?;
    crate::sensor::hesai::atx::AtxFiretimes::parse_binary(&bytes)
        .map_err(|e| format!("{addr}: the sensor's firetime correction: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::TcpListener;
    use std::path::Path;

    /// A fake sensor: answers one PTC request with `reply(command)`.
    fn fake_sensor(reply: impl Fn(u8) -> Vec<u8> + Send + 'static) -> SocketAddr {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap();
        std::thread::spawn(move || {
            if let Ok((mut s, _)) = l.accept() {
                let mut head = [0u8; 8];
                if s.read_exact(&mut head).is_ok() && head[..2] == [0x47, 0x74] {
                    let n = u32::from_be_bytes([head[4], head[5], head[6], head[7]]) as usize;
                    let mut payload = vec![0u8; n];
                    let _ = s.read_exact(&mut payload);
                    let _ = s.write_all(&reply(head[2]));
                }
            }
        });
        addr
    }

    fn response(cmd: u8, code: u8, body: &[u8]) -> Vec<u8> {
        let mut r = vec![0x47, 0x74, cmd, code];
        r.extend_from_slice(&(body.len() as u32).to_be_bytes());
        r.extend_from_slice(body);
        r
    }

    #[test]
    fn fetches_the_angle_correction_from_a_fake_sensor() {
        let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join(
            "../shared/captures/tier4__nebula/src/nebula_hesai/nebula_hesai_decoders/calibration",
        );
        let Ok(csv) = std::fs::read(shared.join("PandarXT32.csv")) else {
            eprintln!("SKIP: {} is absent", shared.display());
            return;
        };
        let served = csv.clone();
        let addr = fake_sensor(move |cmd| response(cmd, 0, &served));
        let got = fetch_angle_correction(addr, Duration::from_secs(5)).unwrap();
        assert_eq!(got, csv);
        // The AT128's binary file comes the same way.
        let dat = std::fs::read(shared.join("PandarAT128.dat")).unwrap();
        let served = dat.clone();
        let addr = fake_sensor(move |cmd| response(cmd, 0, &served));
        assert_eq!(
            fetch_angle_correction(addr, Duration::from_secs(5)).unwrap(),
            dat
        );
    }

    #[test]
    fn errors_of_the_sensor_are_reported() {
        let addr = fake_sensor(|cmd| response(cmd, 0x03, b""));
        let e = fetch_angle_correction(addr, Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("error code 0x03"), "{e}");
        let addr = fake_sensor(|cmd| response(cmd, 0, b"hello"));
        let e = fetch_angle_correction(addr, Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("neither a Hesai CSV"), "{e}");
        let addr = fake_sensor(|_| b"HTTP/1.1 400 Bad Request\r\n\r\n".to_vec());
        let e = fetch_angle_correction(addr, Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("not a PTC response"), "{e}");
        let addr = fake_sensor(|cmd| {
            let mut r = response(cmd, 0, b"");
            r[4..8].copy_from_slice(&u32::MAX.to_be_bytes());
            r
        });
        let e = fetch_angle_correction(addr, Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("refused"), "{e}");
    }

    /// A sensor that sends its answer a byte every 20 ms (a 1 MB file would take 6 hours)
    /// is given up at the time limit of the whole exchange, not of each read. This one stops
    /// after 3 s and closes: a limit per read would have waited for that and reported the
    /// closed connection instead.
    #[test]
    fn a_dripping_sensor_is_given_up_at_the_time_limit() {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap();
        std::thread::spawn(move || {
            if let Ok((mut s, _)) = l.accept() {
                let mut head = [0u8; 8];
                let _ = s.read_exact(&mut head);
                for b in response(GET_ANGLE_CORRECTION, 0, &[b'x'; 1 << 20])
                    .into_iter()
                    .take(150)
                {
                    if s.write_all(&[b]).is_err() {
                        return;
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        });
        let started = Instant::now();
        let e = fetch_angle_correction(addr, Duration::from_millis(500)).unwrap_err();
        assert!(e.contains("no complete response within 500ms"), "{e}");
        // Each read got a byte well within 500 ms: only a limit on the whole exchange ends it.
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{:?}",
            started.elapsed()
        );
    }

    /// The ATX's firetimes come as the binary form (built here from the SDK's struct) and are
    /// read into ns; a sensor without the command answers with an error code, reported.
    #[test]
    fn fetches_the_atx_firetimes_from_a_fake_sensor() {
        let mut bin = vec![0xEE, 0xFF, 4, 1, 0, 0, 2, 10, 0];
        for v in [496u16, 544, 756, 764] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        bin.extend_from_slice(&[0; 32]);
        let addr = fake_sensor(move |cmd| {
            assert_eq!(cmd, GET_FIRETIMES);
            response(cmd, 0, &bin)
        });
        let f = fetch_atx_firetimes(addr, Duration::from_secs(5)).unwrap();
        assert_eq!(f.even_ns, [4_960.0, 5_440.0]);
        assert_eq!(f.odd_ns, [7_560.0, 7_640.0]);
        let addr = fake_sensor(|cmd| response(cmd, 0x01, b""));
        let e = fetch_atx_firetimes(addr, Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("error code 0x01"), "{e}");
        let addr = fake_sensor(|cmd| response(cmd, 0, &[0xEE, 0xFF, 4, 1, 0, 0, 9, 1, 0]));
        let e = fetch_atx_firetimes(addr, Duration::from_secs(5)).unwrap_err();
        assert!(e.contains("firetime correction"), "{e}");
    }
}
