//! The reference quad and hex: the corner numbering, local sides and local edges that every
//! floor above agrees on (what "corner c", "side s" and "edge l" of an element mean).
//!
//! * **Corners** sit at [`HEX_VERTEX_PARAMS`] in \[0, 1\]^3 (a quad's are the first four,
//!   z ignored): VTK/Gmsh order, bottom face 0..3 counter-clockwise, then the top face.
//! * **Local sides** are numbered by parametric direction and end: side `2k + s` is the side
//!   where coordinate k equals s (quad: x0, x1, y0, y1; hex: x0, x1, y0, y1, z0, z1).
//!   [`QUAD_SIDES`] / [`HEX_SIDES`] list their corners, ordered so the side's normal points out
//!   of the element.
//! * **Local edges of a hex** (12) are numbered by direction then position: edge `4k + i` runs
//!   along direction k, from its lower to its upper corner ([`HEX_EDGES`]). A quad's edges are
//!   its sides.

/// Quad sides in order x0, x1, y0, y1 (vertex pairs, counter-clockwise around the quad).
pub const QUAD_SIDES: [[usize; 2]; 4] = [[3, 0], [1, 2], [0, 1], [2, 3]];

/// Hex sides in order x0, x1, y0, y1, z0, z1 (vertex cycles with outward normal).
pub const HEX_SIDES: [[usize; 4]; 6] = [
    [0, 4, 7, 3],
    [1, 2, 6, 5],
    [0, 1, 5, 4],
    [3, 7, 6, 2],
    [0, 3, 2, 1],
    [4, 5, 6, 7],
];

/// Hex edges: 4 along x, then 4 along y, then 4 along z, each from lower to upper vertex.
/// Within a direction the edges are ordered by the other two coordinates (lower first).
pub const HEX_EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [3, 2],
    [4, 5],
    [7, 6],
    [0, 3],
    [1, 2],
    [4, 7],
    [5, 6],
    [0, 4],
    [1, 5],
    [3, 7],
    [2, 6],
];

/// Reference coordinates of the hex vertices (quad: the first four, z ignored).
pub const HEX_VERTEX_PARAMS: [[u8; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];
