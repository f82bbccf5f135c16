//! INRIA 3DGS PLY files, read and write.
//!
//! Vertex properties as INRIA's `save_ply` writes them, all `float`:
//! `x y z nx ny nz f_dc_0..2 f_rest_0..(3(K−1)−1) opacity scale_0..2 rot_0..3`.
//! `f_rest` is channel-major: `f_rest_{c·(K−1)+j}` is coefficient `j+1` of channel `c`.
//! The SH degree is inferred from the number of `f_rest_*` fields (0, 9, 24, 45, 72, 105).
//!
//! Reading accepts `binary_little_endian`, `binary_big_endian` and `ascii`, any scalar
//! property type (converted to f32), properties in any order, and other elements (skipped).
//! Unknown vertex properties are ignored and their names reported in [`PlyInfo`].
//! Writing produces binary little-endian in INRIA's layout (normals written as 0).

use super::{Gaussians, Param};
use crate::error::{Error, Result};
use crate::math::sh::{degree_for_coeffs, num_coeffs};
use std::io::Write;
use std::path::Path;

/// What a read found besides the Gaussians.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyInfo {
    /// Vertex properties that are not part of the INRIA layout, in file order.
    pub ignored_properties: Vec<String>,
    /// Other elements in the file (name, count), skipped.
    pub ignored_elements: Vec<(String, usize)>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    /// Decode one value from exactly `size()` bytes.
    fn decode(self, b: &[u8], le: bool) -> f64 {
        macro_rules! get {
            ($t:ty) => {{
                let a = b.try_into().unwrap();
                if le {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16) as f64,
            Scalar::U16 => get!(u16) as f64,
            Scalar::I32 => get!(i32) as f64,
            Scalar::U32 => get!(u32) as f64,
            Scalar::F32 => get!(f32) as f64,
            Scalar::F64 => get!(f64),
        }
    }
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    /// `None` for a scalar; `Some(count_type)` for a list.
    list_count: Option<Scalar>,
    ty: Scalar,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    body_start: usize,
}

fn parse_header(data: &[u8], path: &Path) -> Result<Header> {
    let err = |m: String| Error::parse(path, m);
    let end = data
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or_else(|| err("not a PLY file: no end_header line".into()))?;
    let mut body_start = end + 10;
    // end_header is followed by "\n" or "\r\n".
    if data.get(body_start) == Some(&b'\r') {
        body_start += 1;
    }
    if data.get(body_start) == Some(&b'\n') {
        body_start += 1;
    }
    let text =
        std::str::from_utf8(&data[..end]).map_err(|_| err("PLY header is not ASCII".into()))?;
    let mut lines = text.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err(err("not a PLY file: first line is not 'ply'".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for l in lines {
        let t: Vec<&str> = l.split_whitespace().collect();
        match t.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _ver] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLe,
                    "binary_big_endian" => Format::BinaryBe,
                    other => return Err(err(format!("unknown PLY format '{other}'"))),
                })
            }
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| err(format!("element '{name}' has invalid count '{count}'")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", ct, ty, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| err("property before element".into()))?;
                let (ct, ty) = (Scalar::parse(ct), Scalar::parse(ty));
                let (Some(ct), Some(ty)) = (ct, ty) else {
                    return Err(err(format!("list property '{name}' has an unknown type")));
                };
                e.props.push(Property {
                    name: name.to_string(),
                    list_count: Some(ct),
                    ty,
                });
            }
            ["property", ty, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| err("property before element".into()))?;
                let ty = Scalar::parse(ty)
                    .ok_or_else(|| err(format!("property '{name}' has unknown type '{ty}'")))?;
                e.props.push(Property {
                    name: name.to_string(),
                    list_count: None,
                    ty,
                });
            }
            _ => return Err(err(format!("unrecognized header line '{l}'"))),
        }
    }
    let format = format.ok_or_else(|| err("PLY header has no format line".into()))?;
    Ok(Header {
        format,
        elements,
        body_start,
    })
}

/// Token source over the body: binary (fixed sizes) or ASCII (whitespace separated).
struct Body<'a> {
    data: &'a [u8],
    pos: usize,
    format: Format,
    path: &'a Path,
}

/// The body positioned at the first row of element `vi`, after checking that the file can
/// hold the announced rows: every row takes at least `row_min` bytes (binary: the scalar
/// sizes and list counts; ASCII: one digit and one separator per property), so a lying
/// count is an error before anything is allocated.
fn vertex_body<'a>(data: &'a [u8], path: &'a Path, header: &Header, vi: usize) -> Result<Body<'a>> {
    let mut body = Body {
        data,
        pos: header.body_start,
        format: header.format,
        path,
    };
    for e in &header.elements[..vi] {
        body.skip_element(e)?;
    }
    let e = &header.elements[vi];
    let row_min: usize = match header.format {
        Format::Ascii => 2 * e.props.len(),
        _ => e
            .props
            .iter()
            .map(|p| p.list_count.unwrap_or(p.ty).size())
            .sum(),
    };
    let left = data.len() - body.pos;
    if row_min.checked_mul(e.count).is_none_or(|need| need > left) {
        return Err(Error::parse(
            path,
            format!(
                "file is truncated: {} {} rows need at least {row_min} bytes each, {left} bytes left",
                e.count, e.name
            ),
        ));
    }
    Ok(body)
}

impl Body<'_> {
    /// The next value of a scalar property, or `None` after skipping a list property.
    fn scalar_or_skip_list(&mut self, p: &Property, row: usize) -> Result<Option<f64>> {
        let Some(ct) = p.list_count else {
            return self.value(p.ty, &p.name).map(Some);
        };
        let len = self.value(ct, &p.name)?;
        if !(0.0..=1e9).contains(&len) {
            return Err(Error::parse(
                self.path,
                format!("row {row}: invalid list length in '{}'", p.name),
            ));
        }
        for _ in 0..len as usize {
            self.value(p.ty, &p.name)?;
        }
        Ok(None)
    }

    fn value(&mut self, ty: Scalar, what: &str) -> Result<f64> {
        match self.format {
            Format::Ascii => {
                let rest = &self.data[self.pos..];
                let start = rest.iter().position(|b| !b.is_ascii_whitespace());
                let Some(start) = start else {
                    return Err(Error::parse(
                        self.path,
                        format!("file ends while reading {what}"),
                    ));
                };
                let len = rest[start..].iter().position(|b| b.is_ascii_whitespace());
                let len = len.unwrap_or(rest.len() - start);
                let tok = std::str::from_utf8(&rest[start..start + len]).unwrap_or("");
                self.pos += start + len;
                tok.parse::<f64>().map_err(|_| {
                    Error::parse(self.path, format!("invalid number '{tok}' for {what}"))
                })
            }
            Format::BinaryLe | Format::BinaryBe => {
                let n = ty.size();
                if self.data.len() - self.pos < n {
                    return Err(Error::parse(
                        self.path,
                        format!("file ends at byte {} while reading {what}", self.data.len()),
                    ));
                }
                let v = ty.decode(
                    &self.data[self.pos..self.pos + n],
                    self.format == Format::BinaryLe,
                );
                self.pos += n;
                Ok(v)
            }
        }
    }

    fn skip_element(&mut self, e: &Element) -> Result<()> {
        // Fixed-size binary elements are skipped in one step, with a size check.
        if self.format != Format::Ascii && e.props.iter().all(|p| p.list_count.is_none()) {
            let row: usize = e.props.iter().map(|p| p.ty.size()).sum();
            let need = row.checked_mul(e.count);
            if need.is_none_or(|n| n > self.data.len() - self.pos) {
                return Err(Error::parse(
                    self.path,
                    format!("element '{}' is truncated", e.name),
                ));
            }
            self.pos += row * e.count;
            return Ok(());
        }
        for row in 0..e.count {
            for p in &e.props {
                self.scalar_or_skip_list(p, row)?;
            }
        }
        Ok(())
    }
}

/// Vertices decoded per read when a file streams ([`read_ply`]): the file's bytes never sit
/// in memory beside the Gaussians made of them, only this many rows (≈ 16 MB at SH 3).
const STREAM_VERTICES: usize = 65_536;

/// The largest header [`read_ply`] looks for `end_header` in before it gives up streaming.
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Read an INRIA 3DGS PLY file. A binary file whose vertices are fixed-size rows (every
/// file INRIA's and gsplat's code writes) streams: its rows are decoded as they are read,
/// so the reader holds at most 65 536 rows of the file beside the Gaussians;
/// any other file is read whole. Both give what [`parse_ply`] gives for the file's bytes,
/// errors included.
pub fn read_ply(path: &Path) -> Result<(Gaussians, PlyInfo)> {
    read_ply_streamed(path, STREAM_VERTICES)
}

fn read_ply_streamed(path: &Path, chunk: usize) -> Result<(Gaussians, PlyInfo)> {
    use std::io::{Read, Seek, SeekFrom};
    let io = |e| Error::io(path, e);
    let mut file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    // The header: read until its end is in the buffer.
    let mut head = Vec::new();
    let mut block = [0u8; 4096];
    let found = loop {
        if head.windows(10).any(|w| w == b"end_header") && head.len() > head_end(&head) {
            break true;
        }
        let n = file.read(&mut block).map_err(io)?;
        if n == 0 || head.len() >= MAX_HEADER_BYTES {
            break false;
        }
        head.extend_from_slice(&block[..n]);
    };
    let whole = |mut file: std::fs::File, mut head: Vec<u8>| {
        file.read_to_end(&mut head).map_err(io)?;
        parse_ply(&head, path)
    };
    if !found {
        return whole(file, head);
    }
    let header = parse_header(&head, path)?;
    let Some(vi) = header.elements.iter().position(|e| e.name == "vertex") else {
        return whole(file, head);
    };
    let fixed = |e: &Element| e.props.iter().all(|p| p.list_count.is_none());
    if header.format == Format::Ascii || !header.elements[..=vi].iter().all(fixed) {
        return whole(file, head);
    }
    let (layout, info) = VertexLayout::new(&header, vi, path)?;
    // The rows' offset and the truncation checks [`vertex_body`] makes on the bytes.
    let row_bytes = |e: &Element| e.props.iter().map(|p| p.ty.size()).sum::<usize>();
    let mut offset = header.body_start as u64;
    for e in &header.elements[..vi] {
        let need = row_bytes(e).checked_mul(e.count).map(|n| n as u64);
        if need.is_none_or(|n| n > len.saturating_sub(offset)) {
            return Err(Error::parse(
                path,
                format!("element '{}' is truncated", e.name),
            ));
        }
        offset += need.unwrap_or(0);
    }
    let vertex = &header.elements[vi];
    let row = row_bytes(vertex);
    let left = len.saturating_sub(offset);
    if row
        .checked_mul(vertex.count)
        .is_none_or(|need| need as u64 > left)
    {
        return Err(Error::parse(
            path,
            format!(
                "file is truncated: {} {} rows need at least {row} bytes each, {left} bytes left",
                vertex.count, vertex.name
            ),
        ));
    }
    file.seek(SeekFrom::Start(offset)).map_err(io)?;
    let mut file = std::io::BufReader::new(file);
    let mut g = layout.gaussians(vertex.count)?;
    let mut buf = vec![0u8; row * chunk.min(vertex.count).max(1)];
    let mut first = 0;
    while first < vertex.count {
        let rows = chunk.min(vertex.count - first);
        let bytes = &mut buf[..rows * row];
        file.read_exact(bytes).map_err(io)?;
        let mut body = Body {
            data: bytes,
            pos: 0,
            format: header.format,
            path,
        };
        layout.decode(&mut body, vertex, first..first + rows, &mut g)?;
        first += rows;
    }
    Ok((g, info))
}

/// Where `end_header`'s line ends in `head` (its newline included), or `head.len()` when
/// that line is not complete yet.
fn head_end(head: &[u8]) -> usize {
    let Some(at) = head.windows(10).position(|w| w == b"end_header") else {
        return head.len();
    };
    match head[at + 10..].iter().position(|&b| b == b'\n') {
        Some(k) => at + 10 + k + 1,
        None => head.len(),
    }
}

/// Parse PLY bytes; `path` names the source in errors.
pub fn parse_ply(data: &[u8], path: &Path) -> Result<(Gaussians, PlyInfo)> {
    let header = parse_header(data, path)?;
    let vi = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| Error::parse(path, "no 'vertex' element".to_string()))?;
    let (layout, info) = VertexLayout::new(&header, vi, path)?;
    let mut body = vertex_body(data, path, &header, vi)?;
    let vertex = &header.elements[vi];
    let mut g = layout.gaussians(vertex.count)?;
    layout.decode(&mut body, vertex, 0..vertex.count, &mut g)?;
    Ok((g, info))
}

/// Where each vertex property goes.
#[derive(Clone, Copy)]
enum Slot {
    Mean(usize),
    Dc(usize),
    Rest(usize),
    Opacity,
    Scale(usize),
    Rot(usize),
    Ignore,
}

/// The vertex element's properties mapped to the Gaussians' fields.
struct VertexLayout<'a> {
    path: &'a Path,
    degree: u32,
    n_rest: usize,
    slots: Vec<Slot>,
}

impl<'a> VertexLayout<'a> {
    /// The layout of element `vi` of `header`, and what the file holds besides.
    fn new(header: &Header, vi: usize, path: &'a Path) -> Result<(Self, PlyInfo)> {
        let err = |m: String| Error::parse(path, m);
        let mut info = PlyInfo::default();
        let vertex = &header.elements[vi];
        for e in &header.elements {
            if e.name != "vertex" {
                info.ignored_elements.push((e.name.clone(), e.count));
            }
        }
        // Map every vertex property to its destination slot.
        let mut n_rest = 0usize;
        for p in &vertex.props {
            if let Some(k) = p.name.strip_prefix("f_rest_") {
                let k: usize = k
                    .parse()
                    .map_err(|_| err(format!("bad property name '{}'", p.name)))?;
                // (Checked before `k + 1`: the fuzzer found f_rest_18446744073709551615.)
                let most = (num_coeffs(crate::math::sh::MAX_SH_DEGREE) - 1) * 3;
                if k >= most {
                    return Err(err(format!(
                        "vertex property '{}': SH degree 5 has {most} f_rest fields",
                        p.name
                    )));
                }
                n_rest = n_rest.max(k + 1);
            }
        }
        let rest_per_channel = n_rest / 3;
        let degree = n_rest
            .is_multiple_of(3)
            .then(|| degree_for_coeffs(rest_per_channel + 1))
            .flatten()
            .ok_or_else(|| {
                err(format!(
                    "{n_rest} f_rest fields do not match an SH degree 0–5 (expected 0, 9, 24, 45, 72 \
                     or 105)"
                ))
            })?;
        let mut seen = vec![false; 3 + 3 + n_rest + 1 + 3 + 4];
        let mut slots = Vec::with_capacity(vertex.props.len());
        for p in &vertex.props {
            let idx = |prefix: &str, n: usize| {
                p.name
                    .strip_prefix(prefix)
                    .and_then(|k| k.parse::<usize>().ok())
                    .filter(|&k| k < n)
            };
            let slot = match p.name.as_str() {
                "x" => Slot::Mean(0),
                "y" => Slot::Mean(1),
                "z" => Slot::Mean(2),
                "opacity" => Slot::Opacity,
                "nx" | "ny" | "nz" => Slot::Ignore,
                _ => {
                    if let Some(k) = idx("f_dc_", 3) {
                        Slot::Dc(k)
                    } else if let Some(k) = idx("f_rest_", n_rest) {
                        Slot::Rest(k)
                    } else if let Some(k) = idx("scale_", 3) {
                        Slot::Scale(k)
                    } else if let Some(k) = idx("rot_", 4) {
                        Slot::Rot(k)
                    } else {
                        info.ignored_properties.push(p.name.clone());
                        Slot::Ignore
                    }
                }
            };
            if p.list_count.is_some() && !matches!(slot, Slot::Ignore) {
                return Err(err(format!(
                    "vertex property '{}' is a list, expected a scalar",
                    p.name
                )));
            }
            let flat = match slot {
                Slot::Mean(k) => Some(k),
                Slot::Dc(k) => Some(3 + k),
                Slot::Rest(k) => Some(6 + k),
                Slot::Opacity => Some(6 + n_rest),
                Slot::Scale(k) => Some(7 + n_rest + k),
                Slot::Rot(k) => Some(10 + n_rest + k),
                Slot::Ignore => None,
            };
            if let Some(f) = flat {
                if seen[f] {
                    return Err(err(format!("vertex property '{}' appears twice", p.name)));
                }
                seen[f] = true;
            }
            slots.push(slot);
        }
        if let Some(missing) = seen.iter().position(|s| !s) {
            let name = match missing {
                0..=2 => ["x", "y", "z"][missing].to_string(),
                3..=5 => format!("f_dc_{}", missing - 3),
                m if m < 6 + n_rest => format!("f_rest_{}", m - 6),
                m if m == 6 + n_rest => "opacity".to_string(),
                m if m < 10 + n_rest => format!("scale_{}", m - 7 - n_rest),
                m => format!("rot_{}", m - 10 - n_rest),
            };
            return Err(err(format!("vertex property '{name}' is missing")));
        }
        Ok((
            VertexLayout {
                path,
                degree,
                n_rest,
                slots,
            },
            info,
        ))
    }

    /// Empty Gaussians of the layout's degree with room for `n`.
    fn gaussians(&self, n: usize) -> Result<Gaussians> {
        let mut g = Gaussians::new(self.degree)?;
        g.means.reserve_exact(n);
        g.sh_dc.reserve_exact(n);
        g.opacity_logits.reserve_exact(n);
        g.log_scales.reserve_exact(n);
        g.quats.reserve_exact(n);
        g.sh_rest.reserve_exact(n * self.n_rest);
        Ok(g)
    }

    /// Decode vertices `rows` (of `vertex.count`) from `body` onto `g`.
    fn decode(
        &self,
        body: &mut Body<'_>,
        vertex: &Element,
        rows: std::ops::Range<usize>,
        g: &mut Gaussians,
    ) -> Result<()> {
        let (path, n, n_rest) = (self.path, vertex.count, self.n_rest);
        let err = |m: String| Error::parse(path, m);
        let rest_per_channel = n_rest / 3;
        let mut rest_cm = [0f32; 105];
        for v in rows {
            let mut mean = [0f32; 3];
            let mut dc = [0f32; 3];
            let mut op = 0f32;
            let mut sc = [0f32; 3];
            let mut rot = [0f32; 4];
            for (p, slot) in vertex.props.iter().zip(&self.slots) {
                let Some(x) = body
                    .scalar_or_skip_list(p, v)
                    .map_err(|e| Error::parse(path, format!("vertex {v} of {n}: {}", e.message)))?
                else {
                    continue;
                };
                let x = x as f32;
                if !x.is_finite() && !matches!(slot, Slot::Ignore) {
                    return Err(err(format!(
                        "vertex {v} of {n}: property '{}' is {x} (a scene holds finite numbers)",
                        p.name
                    )));
                }
                match *slot {
                    Slot::Mean(k) => mean[k] = x,
                    Slot::Dc(k) => dc[k] = x,
                    Slot::Rest(k) => rest_cm[k] = x,
                    Slot::Opacity => op = x,
                    Slot::Scale(k) => sc[k] = x,
                    Slot::Rot(k) => rot[k] = x,
                    Slot::Ignore => {}
                }
            }
            g.means.push(mean);
            g.sh_dc.push(dc);
            g.opacity_logits.push(op);
            g.log_scales.push(sc);
            g.quats.push(rot);
            // Channel-major file order -> coefficient-major memory order.
            for j in 0..rest_per_channel {
                for c in 0..3 {
                    g.sh_rest.push(rest_cm[c * rest_per_channel + j]);
                }
            }
        }
        Ok(())
    }
}

/// A coloured point cloud (COLMAP's `points3D`, INRIA's `points3d.ply`, our datasets'
/// `points3D.ply`). Colours are in `[0, 1]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    pub xyz: Vec<[f32; 3]>,
    pub rgb: Vec<[f32; 3]>,
}

/// Read the `vertex` element of a PLY point cloud: `x y z` (any scalar type) and, when
/// present, `red green blue` (integers scaled by 1/255, floats taken as they are; absent
/// colours are 0.5 grey). Other properties and elements are skipped.
pub fn read_point_cloud(path: &Path) -> Result<PointCloud> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_point_cloud(&data, path)
}

pub fn parse_point_cloud(data: &[u8], path: &Path) -> Result<PointCloud> {
    let header = parse_header(data, path)?;
    let err = |m: String| Error::parse(path, m);
    let vi = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| err("no 'vertex' element".into()))?;
    let vertex = &header.elements[vi];
    let names = ["x", "y", "z", "red", "green", "blue"];
    let slots: Vec<Option<usize>> = vertex
        .props
        .iter()
        .map(|p| {
            names
                .iter()
                .position(|n| *n == p.name)
                .filter(|_| p.list_count.is_none())
        })
        .collect();
    for (k, n) in names.iter().enumerate().take(3) {
        if !slots.contains(&Some(k)) {
            return Err(err(format!("vertex property '{n}' is missing")));
        }
    }
    let has_color = (3..6).all(|k| slots.contains(&Some(k)));
    let mut body = vertex_body(data, path, &header, vi)?;
    let mut pc = PointCloud::default();
    for v in 0..vertex.count {
        let mut vals = [0.5f64; 6];
        for (p, slot) in vertex.props.iter().zip(&slots) {
            let Some(x) = body.scalar_or_skip_list(p, v)? else {
                continue;
            };
            if let Some(k) = *slot {
                let integer_colour = k >= 3 && !matches!(p.ty, Scalar::F32 | Scalar::F64);
                vals[k] = if integer_colour { x / 255.0 } else { x };
            }
        }
        let xyz = [vals[0] as f32, vals[1] as f32, vals[2] as f32];
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(err(format!("vertex {v} has a non-finite position {xyz:?}")));
        }
        pc.xyz.push(xyz);
        pc.rgb.push(if has_color {
            [vals[3] as f32, vals[4] as f32, vals[5] as f32]
        } else {
            [0.5; 3]
        });
    }
    Ok(pc)
}

/// The PLY bytes of `g` in INRIA's binary little-endian layout.
pub fn ply_bytes(g: &Gaussians) -> Result<Vec<u8>> {
    g.validate()?;
    // The reader refuses non-finite values; so does the writer (a diverged training stops
    // with this error instead of saving a scene nothing can read).
    for p in Param::ALL {
        let a = g.param(p);
        if let Some(i) = a.iter().position(|x| !x.is_finite()) {
            return Err(Error::invalid(format!(
                "cannot write a PLY: {} value {i} is {}",
                p.name(),
                a[i]
            )));
        }
    }
    let k1 = num_coeffs(g.sh_degree) - 1;
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header += &format!("element vertex {}\n", g.len());
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    names.extend((0..3 * k1).map(|k| format!("f_rest_{k}")));
    names.push("opacity".into());
    names.extend((0..3).map(|k| format!("scale_{k}")));
    names.extend((0..4).map(|k| format!("rot_{k}")));
    for n in &names {
        header += &format!("property float {n}\n");
    }
    header += "end_header\n";
    let mut out = Vec::with_capacity(header.len() + g.len() * names.len() * 4);
    out.extend_from_slice(header.as_bytes());
    for i in 0..g.len() {
        let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
        g.means[i].iter().for_each(|&v| put(v));
        (0..3).for_each(|_| put(0.0));
        g.sh_dc[i].iter().for_each(|&v| put(v));
        let rest = g.rest(i);
        for c in 0..3 {
            for j in 0..k1 {
                put(rest[j * 3 + c]);
            }
        }
        put(g.opacity_logits[i]);
        g.log_scales[i].iter().for_each(|&v| put(v));
        g.quats[i].iter().for_each(|&v| put(v));
    }
    Ok(out)
}

/// Write `g` as an INRIA PLY, atomically (temporary file, then rename).
pub fn write_ply(g: &Gaussians, path: &Path) -> Result<()> {
    let bytes = ply_bytes(g)?;
    crate::io::write_atomic(path, |f| f.write_all(&bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder removed when dropped, even when the test fails.
    struct Folder(std::path::PathBuf);
    impl Drop for Folder {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// `bytes` with every 4-byte word after the header reversed (a float-only body in the
    /// other byte order).
    fn swapped(bytes: &[u8], body: usize) -> Vec<u8> {
        let mut out = bytes[..body].to_vec();
        for w in bytes[body..].chunks(4) {
            out.extend(w.iter().rev());
        }
        out
    }

    /// A streamed read (several chunk sizes) gives what parsing the whole file gives:
    /// the same Gaussians and report, or the same error, on little- and big-endian files,
    /// with an element before the vertices, ASCII (read whole), truncated anywhere, or with
    /// a non-finite value in a later chunk.
    #[test]
    fn a_streamed_read_is_the_whole_files_parse() {
        let dir = std::env::temp_dir().join(format!("unseen-ply-stream-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let _guard = Folder(dir.clone());
        // 300 Gaussians at SH degree 3 with distinct values (the `scene` module lies above).
        let mut g = Gaussians::new(3).unwrap();
        let f = |i: usize, k: usize| ((i * 131 + k * 17) % 997) as f32 / 997.0 - 0.5;
        for i in 0..300 {
            g.means.push([f(i, 0), f(i, 1), 2.0 + f(i, 2)]);
            g.sh_dc.push([f(i, 3), f(i, 4), f(i, 5)]);
            g.opacity_logits.push(f(i, 6));
            g.log_scales
                .push([f(i, 7) - 3.0, f(i, 8) - 3.0, f(i, 9) - 3.0]);
            g.quats.push([1.0, f(i, 10), f(i, 11), f(i, 12)]);
            g.sh_rest.extend((0..45).map(|k| f(i, 13 + k)));
        }
        let le = ply_bytes(&g).unwrap();
        let body = le.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let header = std::str::from_utf8(&le[..body]).unwrap();
        let mut cases: Vec<(String, Vec<u8>)> = vec![("le".into(), le.clone())];
        cases.push((
            "be".into(),
            [
                header
                    .replace("binary_little_endian", "binary_big_endian")
                    .as_bytes(),
                &swapped(&le, body)[body..],
            ]
            .concat(),
        ));
        let with_face = header.replace(
            "element vertex",
            "element face 2\nproperty int a\nproperty uchar b\nelement vertex",
        );
        cases.push((
            "element before".into(),
            [with_face.as_bytes(), &[1u8; 10], &le[body..]].concat(),
        ));
        let mut nan = le.clone();
        let row = (le.len() - body) / 300;
        nan[body + 250 * row..body + 250 * row + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        cases.push(("nan".into(), nan));
        for cut in [
            0,
            5,
            body - 3,
            body,
            body + 1,
            body + 17 * row + 3,
            le.len() - 1,
        ] {
            cases.push((format!("cut at {cut}"), le[..cut].to_vec()));
        }
        let mut ascii = String::from(header).replace("binary_little_endian", "ascii");
        for v in 0..3 {
            let words: Vec<String> = le[body + v * row..body + (v + 1) * row]
                .chunks(4)
                .map(|w| f32::from_le_bytes(w.try_into().unwrap()).to_string())
                .collect();
            ascii += &(words.join(" ") + "\n");
        }
        cases.push((
            "ascii".into(),
            ascii.replace("vertex 300", "vertex 3").into_bytes(),
        ));
        for (name, bytes) in cases {
            let path = dir.join("scene.ply");
            std::fs::write(&path, &bytes).unwrap();
            let whole = parse_ply(&bytes, &path).map_err(|e| e.to_string());
            for chunk in [1, 7, 1 << 20] {
                let streamed = read_ply_streamed(&path, chunk).map_err(|e| e.to_string());
                assert_eq!(streamed, whole, "{name}, chunks of {chunk}");
            }
            if name == "le" || name == "be" || name == "element before" {
                assert_eq!(whole.as_ref().unwrap().0, g, "{name}");
            }
        }
    }
}
