#!/usr/bin/env python3
"""Independent check of VTU files with VTK's own reader and Lagrange cell evaluation.

usage: vtk_probe.py JOBS.json
JOBS.json: {"jobs": [{"file": "a.vtu", "probes": [[cell_index, u, v, w], ...]}, ...]} with
(u, v, w) in VTK's parametric [0,1]^d. Prints a JSON list, one object per job:
{"cells": n, "points": n, "types": {type: count}, "probed": [[x, y, z], ...]}.
"""
import json
import sys

from vtkmodules.vtkCommonCore import reference
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader


def probe(path, probes):
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(path)
    reader.Update()
    grid = reader.GetOutput()
    types = {}
    for i in range(grid.GetNumberOfCells()):
        t = grid.GetCellType(i)
        types[str(t)] = types.get(str(t), 0) + 1
    probed = []
    for c, u, v, w in probes:
        cell = grid.GetCell(int(c))
        x = [0.0, 0.0, 0.0]
        weights = [0.0] * cell.GetNumberOfPoints()
        cell.EvaluateLocation(reference(0), [u, v, w], x, weights)
        probed.append(x)
    return {"cells": grid.GetNumberOfCells(), "points": grid.GetNumberOfPoints(), "types": types, "probed": probed}


def main():
    jobs = json.load(open(sys.argv[1]))["jobs"]
    print(json.dumps([probe(j["file"], j["probes"]) for j in jobs]))


if __name__ == "__main__":
    main()
