//! LZ4 frames (the LZ4 Frame Format, `lz4_Frame_format.md` 1.6) decompressed straight into the
//! buffer their records are read from: ROS 1 bags' `lz4` chunks and MCAP's `lz4` chunks.
//!
//! The `lz4` crate's streaming decoder (liblz4's frame API) copied its own input into a buffer
//! and, for linked blocks, the last 64 KiB of its output after every call: 13 % of the
//! instructions of decoding an lz4 ROS 1 bag were those copies. Here the frame is walked by
//! hand and each block goes to `lz4_flex`'s block decoder, which writes into the chunk's buffer
//! and reads linked blocks' matches from the bytes it wrote just before.
//!
//! Layout: magic `04 22 4D 18`; FLG (version 01, block independence, block checksum, content
//! size, content checksum, a reserved 0 bit, dictionary id); BD (block maximum size 4–7 = 64 KiB
//! – 4 MiB); the content size (8 bytes) and dictionary id (4 bytes) when flagged; HC, the second
//! byte of the descriptor's xxHash-32. Then blocks: a u32 size whose top bit marks a stored
//! (uncompressed) block, its bytes, its xxHash-32 when flagged; a zero size ends the frame, then
//! the content's xxHash-32 when flagged. Frames may follow one another; skippable frames (magic
//! `5X 2A 4D 18`) are skipped. Every checksum present is checked. A dictionary id (an external
//! dictionary) is refused: nothing here could supply one.

use twox_hash::XxHash32;

const MAGIC: u32 = 0x184D_2204;
const SKIPPABLE: u32 = 0x184D_2A50;
/// Back-references of a linked block reach this far into the frame's earlier output.
const WINDOW: usize = 64 << 10;

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(
        b.get(at..at.checked_add(4)?)?.try_into().ok()?,
    ))
}

/// Decompresses the frames of `src` into `out[..size]`; `out` grows a block at a time as
/// output arrives (never past `size` plus one block) and is never shrunk. An error says what is
/// wrong; so does output that is not exactly `size` bytes.
pub(crate) fn decompress(src: &[u8], size: usize, out: &mut Vec<u8>) -> Result<(), String> {
    let mut at = 0usize;
    let mut pos = 0usize;
    let cut = || "the frame is cut short".to_string();
    while at < src.len() {
        let magic = u32_at(src, at).ok_or_else(cut)?;
        if magic & 0xFFFF_FFF0 == SKIPPABLE {
            let len = u32_at(src, at + 4).ok_or_else(cut)? as usize;
            at = at
                .checked_add(8 + len)
                .filter(|&e| e <= src.len())
                .ok_or_else(cut)?;
            continue;
        }
        if magic != MAGIC {
            return Err(format!("no LZ4 frame magic at byte {at} ({magic:08x})"));
        }
        let (flg, bd) = match src.get(at + 4..at + 6) {
            Some(&[f, b]) => (f, b),
            _ => return Err(cut()),
        };
        if flg >> 6 != 1 || flg & 0x02 != 0 || bd & 0x8F != 0 {
            return Err(format!(
                "LZ4 frame descriptor {flg:02x} {bd:02x} is not version 1"
            ));
        }
        if flg & 0x01 != 0 {
            return Err("the LZ4 frame needs an external dictionary".into());
        }
        let (linked, block_sums, content_sum) = (flg & 0x20 == 0, flg & 0x10 != 0, flg & 0x04 != 0);
        let block_max: usize = match (bd >> 4) & 7 {
            4 => 64 << 10,
            5 => 256 << 10,
            6 => 1 << 20,
            7 => 4 << 20,
            n => return Err(format!("LZ4 block size id {n}")),
        };
        let descriptor_end = at + 6 + if flg & 0x08 != 0 { 8 } else { 0 };
        let descriptor = src.get(at + 4..descriptor_end).ok_or_else(cut)?;
        let hc = *src.get(descriptor_end).ok_or_else(cut)?;
        if (XxHash32::oneshot(0, descriptor) >> 8) as u8 != hc {
            return Err("LZ4 frame header checksum mismatch".into());
        }
        at = descriptor_end + 1;
        let frame_start = pos;
        loop {
            let word = u32_at(src, at).ok_or_else(cut)?;
            at += 4;
            if word == 0 {
                break;
            }
            let stored = word & 0x8000_0000 != 0;
            let n = (word & 0x7FFF_FFFF) as usize;
            if n > block_max {
                return Err(format!(
                    "an LZ4 block of {n} bytes in a frame of {block_max}-byte blocks"
                ));
            }
            let data = src.get(at..at + n).ok_or_else(cut)?;
            at += n;
            if block_sums {
                let sum = u32_at(src, at).ok_or_else(cut)?;
                at += 4;
                if XxHash32::oneshot(0, data) != sum {
                    return Err("LZ4 block checksum mismatch".into());
                }
            }
            let room = size - pos;
            let end = pos + block_max.min(room);
            if out.len() < end {
                out.resize(end, 0);
            }
            if stored {
                if n > room {
                    return Err(format!(
                        "LZ4 frames hold more than the {size} bytes claimed"
                    ));
                }
                out[pos..pos + n].copy_from_slice(data);
                pos += n;
                continue;
            }
            let (before, after) = out.split_at_mut(pos);
            let dict = if linked {
                &before[frame_start.max(pos.saturating_sub(WINDOW))..]
            } else {
                &[][..]
            };
            pos += lz4_flex::block::decompress_into_with_dict(data, &mut after[..end - pos], dict)
                .map_err(|e| format!("an LZ4 block does not decompress: {e}"))?;
        }
        if content_sum {
            let sum = u32_at(src, at).ok_or_else(cut)?;
            at += 4;
            if XxHash32::oneshot(0, &out[frame_start..pos]) != sum {
                return Err("LZ4 content checksum mismatch".into());
            }
        }
    }
    if pos != size {
        return Err(format!(
            "LZ4 frames hold {pos} bytes, not the {size} claimed"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// `data` through liblz4's frame encoder (the `lz4` crate), an independent writer.
    fn frame(data: &[u8], size: lz4::BlockSize, mode: lz4::BlockMode, sums: bool) -> Vec<u8> {
        let mut e = lz4::EncoderBuilder::new()
            .block_size(size)
            .block_mode(mode)
            .checksum(if sums {
                lz4::ContentChecksum::ChecksumEnabled
            } else {
                lz4::ContentChecksum::NoChecksum
            })
            .build(Vec::new())
            .unwrap();
        e.write_all(data).unwrap();
        let (v, r) = e.finish();
        r.unwrap();
        v
    }

    /// Compressible bytes with matches reaching back across block boundaries.
    fn sample(n: usize) -> Vec<u8> {
        let mut s = 0x1234_5678u32;
        let mut v = Vec::with_capacity(n);
        while v.len() < n {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            if s >> 28 < 6 && v.len() > 70_000 {
                let back = 1 + (s as usize >> 8) % 65_000;
                let k = v.len() - back;
                for i in 0..(s as usize >> 4) % 40 {
                    let b = v[k + i];
                    v.push(b);
                }
            } else {
                v.push((s >> 24) as u8 % 7);
            }
        }
        v.truncate(n);
        v
    }

    #[test]
    fn liblz4_frames_decompress_to_their_bytes() {
        let data = sample(3_000_000);
        for size in [
            lz4::BlockSize::Max64KB,
            lz4::BlockSize::Max1MB,
            lz4::BlockSize::Max4MB,
        ] {
            for mode in [lz4::BlockMode::Linked, lz4::BlockMode::Independent] {
                for sums in [false, true] {
                    let f = frame(&data, size.clone(), mode.clone(), sums);
                    // A buffer used before (longer, other bytes) as the readers reuse theirs.
                    let mut out = vec![0xAB; 5_000_000];
                    decompress(&f, data.len(), &mut out).unwrap();
                    assert!(out[..data.len()] == data[..]);
                    // Two frames back to back, and a skippable frame between them.
                    let mut two = f.clone();
                    two.extend_from_slice(&0x184D_2A53u32.to_le_bytes());
                    two.extend_from_slice(&3u32.to_le_bytes());
                    two.extend_from_slice(b"xyz");
                    two.extend_from_slice(&f);
                    let mut out = Vec::new();
                    decompress(&two, 2 * data.len(), &mut out).unwrap();
                    assert!(
                        out[..data.len()] == data[..]
                            && out[data.len()..2 * data.len()] == data[..]
                    );
                }
            }
        }
    }

    #[test]
    fn a_frame_written_by_hand_from_the_format() {
        // FLG 0x60: version 01, independent blocks, no checksums, no size; BD 0x40: 64 KiB.
        // HC = (xxh32(60 40) >> 8) & 0xFF = 0x82 (the header of `lz4 -BD`-free empty frames).
        let mut f = vec![0x04, 0x22, 0x4D, 0x18, 0x60, 0x40, 0x82];
        // A stored block "abc", then a compressed block: token 0x34 = 3 literals "xyz" and a
        // match of 4 + 4 = 8 bytes at offset 3 ("xyzxyzxy"), then the closing literals-only
        // sequence, empty (token 0x00).
        f.extend_from_slice(&(0x8000_0003u32).to_le_bytes());
        f.extend_from_slice(b"abc");
        let block = [0x34, b'x', b'y', b'z', 3, 0, 0x00];
        f.extend_from_slice(&(block.len() as u32).to_le_bytes());
        f.extend_from_slice(&block);
        f.extend_from_slice(&0u32.to_le_bytes());
        let mut out = Vec::new();
        decompress(&f, 14, &mut out).unwrap();
        assert_eq!(&out[..14], b"abcxyzxyzxyzxy");
    }

    #[test]
    fn damaged_frames_are_errors() {
        let data = sample(300_000);
        let f = frame(&data, lz4::BlockSize::Max64KB, lz4::BlockMode::Linked, true);
        let mut out = Vec::new();
        // The wrong size, every cut, a flipped byte anywhere: an error, never a panic.
        assert!(decompress(&f, data.len() - 1, &mut out).is_err());
        assert!(decompress(&f, data.len() + 1, &mut out).is_err());
        for cut in (0..f.len()).step_by(997) {
            assert!(
                decompress(&f[..cut], data.len(), &mut out).is_err(),
                "cut {cut}"
            );
        }
        for i in (0..f.len()).step_by(331) {
            let mut g = f.clone();
            g[i] ^= 0x5A;
            assert!(decompress(&g, data.len(), &mut out).is_err(), "byte {i}");
        }
        // A block claiming more than the frame's block size; a dictionary frame.
        let mut g = f.clone();
        g[7..11].copy_from_slice(&(0x10_0000u32).to_le_bytes());
        assert!(decompress(&g, data.len(), &mut out)
            .unwrap_err()
            .contains("block of"));
        let mut g = f;
        g[4] |= 0x01;
        assert!(decompress(&g, data.len(), &mut out).is_err());
    }
}
