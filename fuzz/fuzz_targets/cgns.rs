//! The CGNS/HDF5 reader on arbitrary bytes, then the checks every accepted file goes through.
#![no_main]

use libfuzzer_sys::fuzz_target;
use polyspline::io::Format;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};

fuzz_target!(|data: &[u8]| {
    if let Ok(raw) = Format::Cgns.parse(data)
        && let Ok(mesh) = LinearMesh::from_raw(raw, &MeshOptions::default())
    {
        let topo = Topology::build(&mesh);
        let _ = polyspline::mesh::manifold::check_curvable(&mesh, &topo);
    }
});
