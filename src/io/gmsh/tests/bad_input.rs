//! Malformed MSH input: every error is one bounded message at the right place, never a panic.

use super::*;

fn err(data: &[u8]) -> ParseError {
    match read(data) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e,
    }
}

fn err_str(s: &str) -> ParseError {
    err(s.as_bytes())
}

const HEAD: &str = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
const NODES: &str = "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n";

#[test]
fn garbage_and_empty() {
    assert_eq!(err(b"").location, Location::File);
    assert_eq!(err(b"  \n\n").location, Location::File);
    let e = err(b"\xff\xfe\x00garbage\n");
    assert_eq!(e.location, Location::Line(1));
    assert!(e.message.contains("$MeshFormat"), "{}", e.message);
    let e = err_str("$Nodes\n1\n1 0 0 0\n$EndNodes\n");
    assert_eq!(e.location, Location::Line(1));
    let e = err_str("$MeshFormat\n3.0 0 8\n$EndMeshFormat\n");
    assert!(e.message.contains("3.0"), "{}", e.message);
    let e = err_str("$MeshFormat\n2.2 2 8\n$EndMeshFormat\n");
    assert_eq!(e.location, Location::Line(2));
    let e = err_str(&format!("{HEAD}{NODES}junk\n"));
    assert_eq!(e.location, Location::Line(11));
    let e = err_str(&format!("{HEAD}$EndNodes\n"));
    assert_eq!(e.location, Location::Line(4));
}

#[test]
fn truncated_ascii() {
    let full = format!("{HEAD}{NODES}$Elements\n1\n1 3 2 0 1 1 2 3 4\n$EndElements\n");
    assert!(read(full.as_bytes()).is_ok());
    let e = err_str(&full[..full.len() - 20]);
    assert_eq!(e.location, Location::Line(13));
    assert!(e.message.contains("end of file"), "{}", e.message);
    let e = err_str(&format!("{HEAD}$Nodes\n4\n1 0 0 0\n2 1 0"));
    assert_eq!(e.location, Location::Line(7));
    assert!(
        e.message.contains("z coordinate of node 2"),
        "{}",
        e.message
    );
    // Every prefix either parses or fails cleanly.
    for n in 0..full.len() {
        let _ = read(&full.as_bytes()[..n]);
    }
}

#[test]
fn wrong_counts() {
    // Fewer nodes than declared: the $EndNodes token is met where a node tag is expected.
    let e = err_str(&format!("{HEAD}$Nodes\n5\n1 0 0 0\n2 1 0 0\n$EndNodes\n"));
    assert_eq!(e.location, Location::Line(8));
    assert!(e.message.contains("tag of node 3 of 5"), "{}", e.message);
    // More nodes than declared.
    let e = err_str(&format!("{HEAD}$Nodes\n1\n1 0 0 0\n2 1 0 0\n$EndNodes\n"));
    assert_eq!(e.location, Location::Line(7));
    assert!(e.message.contains("$EndNodes"), "{}", e.message);
    // MSH 4.1 block counts that disagree with the header.
    let e = err_str(
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 3 1 2\n0 1 0 2\n1\n2\n0 0 0\n1 0 0\n$EndNodes\n",
    );
    assert_eq!(e.location, Location::Line(10));
    assert!(e.message.contains("declares 3 nodes"), "{}", e.message);
    // Huge counts do not allocate.
    let e = err_str(&format!("{HEAD}$Nodes\n18446744073709551615\n1 0 0 0\n"));
    assert!(matches!(e.location, Location::Line(_)));
    let e = err_str(&format!("{HEAD}$Nodes\n99999999999999999999999\n"));
    assert!(e.message.contains("number of nodes"), "{}", e.message);
}

#[test]
fn bad_tokens_and_indices() {
    let el = |line: &str| format!("{HEAD}{NODES}$Elements\n1\n{line}\n$EndElements\n");
    let e = err_str(&el("1 3 2 0 1 1 2 x 4"));
    assert_eq!(e.location, Location::Line(13));
    assert!(
        e.message.contains("node 3 of 4 of element 1"),
        "{}",
        e.message
    );
    let e = err_str(&el("1 3 2 0 1 1 2 -3 4"));
    assert_eq!(e.location, Location::Line(13));
    let e = err_str(&el("1 3 2 0 1 1 2 5 4"));
    assert_eq!(e.location, Location::Line(13));
    assert!(e.message.contains("node 5"), "{}", e.message);
    assert!(e.message.contains("does not define"), "{}", e.message);
    let e = err_str(&el("1 77 2 0 1 1 2 3 4"));
    assert_eq!(e.location, Location::Line(13), "{e}");
    assert!(
        e.message.contains("unknown Gmsh element type 77"),
        "{}",
        e.message
    );
    let e = err_str(&el("1 3 2 99999999999 1 1 2 3 4"));
    assert!(e.message.contains("out of range"), "{}", e.message);
    let e = err_str(&format!("{HEAD}$Nodes\n2\n1 0 0 0\n1 1 0 0\n$EndNodes\n"));
    assert_eq!(e.location, Location::Line(7));
    assert!(
        e.message.contains("defined twice (first at line 6)"),
        "{}",
        e.message
    );
    let e = err_str(&format!("{HEAD}$Nodes\n1\n1 0 zero 0\n$EndNodes\n"));
    assert_eq!(e.location, Location::Line(6));
    assert!(
        e.message.contains("y coordinate of node 1"),
        "{}",
        e.message
    );
    let e = err_str(&format!("{HEAD}$Elements\n0\n$EndElements\n"));
    assert!(e.message.contains("before the $Nodes"), "{}", e.message);
    let e = err_str(&format!("{HEAD}$Periodic\n1\n"));
    assert_eq!(e.location, Location::Line(4));
    assert!(e.message.contains("before the $Nodes"), "{}", e.message);
}

/// Malformed `$Periodic` sections (MSH 2.2, 4.1 ASCII and binary): one message at the place.
#[test]
fn bad_periodic_sections() {
    let v2 = |body: &str| format!("{HEAD}{NODES}$Periodic\n{body}$EndPeriodic\n");
    for (body, line, says) in [
        // Truncated link.
        ("1\n1 2\n", 14, "master entity tag of periodic link 1 of 1"),
        // More links than the section holds.
        (
            "2\n1 2 4\n1\n2 1\n",
            16,
            "dimension of periodic link 2 of 2",
        ),
        // A node tag $Nodes does not define.
        ("1\n1 2 4\n1\n2 9\n", 15, "names node 9"),
        // A short affine line.
        (
            "1\n1 2 4\nAffine 1 0 0\n1\n2 1\n",
            14,
            "has 3 values, expected 16",
        ),
        (
            "1\n1 2 4\nAffine 1 0 x 0 1 0 0 0 0 1 0 0 0 0 1\n1\n2 1\n",
            14,
            "affine value 3 of 16",
        ),
        // An absurd node pair count.
        ("1\n1 2 4\n99999999999\n", 14, "99999999999 node pairs"),
        // Fewer pairs than declared.
        ("1\n1 2 4\n2\n2 1\n", 16, "node of node pair 2 of 2"),
    ] {
        let e = err_str(&v2(body));
        assert_eq!(e.location, Location::Line(line), "{body:?}: {e}");
        assert!(e.message.contains(says), "{body:?}: {e}");
    }
    let v41 = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2 1 2\n2 1 0 2\n1\n2\n0 0 0\n1 0 0\n$EndNodes\n";
    for (body, says) in [
        ("1\n1 2 4\n3 1 0 0\n1\n2 1\n", "affine map of 3 values"),
        ("1\n1 2 4\n0\n1\n2 3\n", "names node 3"),
        (
            "1\n1 2 4\n0\n2\n2 1\n$EndPeriodic\n",
            "node of node pair 2 of 2",
        ),
    ] {
        let e = err_str(&format!("{v41}$Periodic\n{body}$EndPeriodic\n"));
        assert!(e.message.contains(says), "{body:?}: {e}");
    }
    // MSH 4.1 binary: counts that do not fit, a node out of range, a truncated section.
    let bin_head = |links: u64| {
        let mut d = b"$MeshFormat\n4.1 1 8\n".to_vec();
        d.extend(1i32.to_le_bytes());
        d.extend(b"\n$EndMeshFormat\n$Nodes\n");
        for v in [1u64, 2, 1, 2] {
            d.extend(v.to_le_bytes());
        }
        for v in [2i32, 1, 0] {
            d.extend(v.to_le_bytes());
        }
        d.extend(2u64.to_le_bytes());
        d.extend(1u64.to_le_bytes());
        d.extend(2u64.to_le_bytes());
        for c in [0.0f64, 0.0, 0.0, 1.0, 0.0, 0.0] {
            d.extend(c.to_le_bytes());
        }
        d.extend(b"\n$EndNodes\n$Periodic\n");
        d.extend(links.to_le_bytes());
        for v in [1i32, 2, 4] {
            d.extend(v.to_le_bytes());
        }
        d
    };
    let mut huge = bin_head(1);
    huge.extend(0u64.to_le_bytes());
    huge.extend(u64::MAX.to_le_bytes());
    let mut out_of_range = bin_head(1);
    out_of_range.extend(0u64.to_le_bytes());
    out_of_range.extend(1u64.to_le_bytes());
    out_of_range.extend(2u64.to_le_bytes());
    out_of_range.extend(7u64.to_le_bytes());
    out_of_range.extend(b"\n$EndPeriodic\n");
    let mut bad_affine = bin_head(1);
    bad_affine.extend(5u64.to_le_bytes());
    let truncated = bin_head(2);
    for (data, says) in [
        (huge, "do not fit"),
        (out_of_range, "names node 7"),
        (bad_affine, "affine map of 5 values"),
        (truncated, "periodic link 1 of 2"),
    ] {
        let e = err(&data);
        assert!(matches!(e.location, Location::Byte(_)), "{e}");
        assert!(e.message.contains(says), "{e}");
        assert!(
            e.to_string().len() < 400 && !e.to_string().contains('\n'),
            "{e}"
        );
    }
}

#[test]
fn v41_bad_input() {
    let bad_node = V41_PARTIAL.replace("2 10 20 21 900", "2 10 20 22 900");
    let e = err_str(&bad_node);
    assert_eq!(e.location, Location::Line(31));
    assert!(e.message.contains("node 22"), "{}", e.message);
    let bad_type = V41_PARTIAL.replace("2 2 3 1\n", "2 2 77 1\n");
    let e = err_str(&bad_type);
    assert_eq!(e.location, Location::Line(30));
    let bad_dim = V41_PARTIAL.replace("2 1 0 4\n", "7 1 0 4\n");
    assert_eq!(err_str(&bad_dim).location, Location::Line(11));
    for n in 0..V41_PARTIAL.len() {
        let _ = read(&V41_PARTIAL.as_bytes()[..n]);
    }
}

#[test]
fn binary_truncated_or_corrupt() {
    for name in ["box_22_bin.msh", "box_41_bin.msh", "ball_41_bin.msh"] {
        let data = fixture(name);
        // Cut inside the element records: a byte offset in the element data.
        let el = data.windows(10).position(|w| w == b"$Elements\n").unwrap();
        let end = data
            .windows(13)
            .position(|w| w == b"$EndElements\n")
            .unwrap();
        let e = err(&data[..(el + end) / 2]);
        let Location::Byte(b) = e.location else {
            panic!("{name}: {e}")
        };
        assert!(b > el && b < end, "{name}: {e}");
        assert!(
            e.message.contains("file ends") || e.message.contains("do not fit"),
            "{name}: {}",
            e.message
        );
        // No prefix panics.
        for n in (0..data.len()).step_by(7) {
            let _ = read(&data[..n]);
        }
        // Nor does flipping bytes.
        let mut rng = 0x1234_5678_u64;
        for _ in 0..300 {
            let mut d = data.clone();
            for _ in 0..4 {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let i = (rng >> 33) as usize % d.len();
                d[i] = (rng >> 17) as u8;
            }
            let _ = read(&d);
        }
    }
    // Byte order marker that is not 1.
    let mut d = v22_binary(false);
    let at = d.windows(8).position(|w| w == b"2.2 1 8\n").unwrap() + 8;
    d[at] = 2;
    assert_eq!(err(&d).location, Location::Byte(at));
    // A huge node count in a 4.1 binary header is refused before any allocation.
    let data = fixture("box_41_bin.msh");
    let nodes = data.windows(7).position(|w| w == b"$Nodes\n").unwrap() + 7;
    let mut d = data.clone();
    d[nodes + 16..nodes + 24].copy_from_slice(&u64::MAX.to_le_bytes());
    let mut d2 = data.clone();
    // First block's node count.
    d2[nodes + 32 + 12..nodes + 32 + 20].copy_from_slice(&(1u64 << 60).to_le_bytes());
    let e = err(&d2);
    assert!(e.message.contains("do not fit"), "{}", e.message);
    let _ = read(&d);
    // An undefined node in a binary element record.
    let mut d = v22_binary(false);
    let n = d.len();
    d[n - 14 - 16..n - 14 - 12].copy_from_slice(&77i32.to_le_bytes());
    let e = err(&d);
    assert!(e.message.contains("node 77"), "{}", e.message);
    assert!(matches!(e.location, Location::Byte(_)));
}

#[test]
fn random_fragments_never_panic() {
    let fragments = [
        "$MeshFormat\n",
        "2.2 0 8\n",
        "4.1 0 8\n",
        "4.0 0 8\n",
        "2.2 1 8\n",
        "4.1 1 4\n",
        "$EndMeshFormat\n",
        "$Nodes\n",
        "$EndNodes\n",
        "$Elements\n",
        "$EndElements\n",
        "$Entities\n",
        "$EndEntities\n",
        "$PhysicalNames\n",
        "\"a b\"\n",
        "$NOD\n",
        "$ELM\n",
        "$PartitionedEntities\n",
        "1 ",
        "0 ",
        "3 ",
        "5 ",
        "-1 ",
        "99999999999 ",
        "1e300 ",
        "nan ",
        "\n",
        "\u{e9}",
        "$\u{e9}\u{e9}",
        "$End",
        "\x01\x00\x00\x00",
        "\r\n",
        "$Endx",
        "18446744073709551615 ",
    ];
    let mut rng = 0x9e37_79b9_7f4a_7c15_u64;
    for _ in 0..20000 {
        let mut s = String::new();
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let n = (rng >> 58) as usize;
        for _ in 0..n {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            s.push_str(fragments[(rng >> 33) as usize % fragments.len()]);
        }
        let _ = read(s.as_bytes());
    }
    let _ = read("$\u{e9}\u{e9}".as_bytes());
}
