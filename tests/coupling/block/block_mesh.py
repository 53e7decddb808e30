#!/usr/bin/python3
"""Writes a rubber block for the sphere-on-block verification (issue 16) as
Gmsh .msh 4.1 ASCII: a box [-L, L] x [-L, L] x [-D, 0] of linear tetrahedra
(6 per hexahedral cell, Kuhn split), cells of size h within +-f of the axis
and within f of the top, growing by `grow` per cell beyond (tensor grading).
Physical groups: "rim" = the bottom face (fixed), "contact" = the top face.

    block_mesh.py OUT.msh h [L D f grow]     (m; defaults 0.025 0.025 0.007 1.25)
"""
import sys

import numpy as np


def axis(h, f, extent, grow):
    """Coordinates from 0 to extent: cells of h up to f, then growing."""
    xs = [0.0]
    while xs[-1] < f - 1e-12:
        xs.append(min(xs[-1] + h, f))
    step = h
    while xs[-1] < extent - 1e-12:
        step *= grow
        nxt = xs[-1] + step
        if extent - nxt < 0.5 * step * grow:  # last cell takes the rest
            nxt = extent
        xs.append(min(nxt, extent))
    return np.array(xs)


def main():
    out, h = sys.argv[1], float(sys.argv[2])
    L = float(sys.argv[3]) if len(sys.argv) > 3 else 0.025
    D = float(sys.argv[4]) if len(sys.argv) > 4 else 0.025
    f = float(sys.argv[5]) if len(sys.argv) > 5 else 0.007
    grow = float(sys.argv[6]) if len(sys.argv) > 6 else 1.25
    half = axis(h, f, L, grow)
    xy = np.concatenate([-half[:0:-1], half])
    z = -axis(h, f, D, grow)[::-1]
    nx, ny, nz = len(xy), len(xy), len(z)
    X, Y, Z = np.meshgrid(xy, xy, z, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    # the hexahedron's corners c[b] with b = (dx, dy, dz) bits; Kuhn split along 0-7
    c = [idx[(b & 1):nx - 1 + (b & 1), (b >> 1 & 1):ny - 1 + (b >> 1 & 1), (b >> 2 & 1):nz - 1 + (b >> 2 & 1)].ravel()
         for b in range(8)]
    paths = [(1, 3), (1, 5), (2, 3), (2, 6), (4, 5), (4, 6)]
    tets = np.concatenate([np.stack([c[0], c[a], c[b], c[7]], axis=1) for a, b in paths])
    # positive volume
    p = pts[tets]
    vol = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    neg = vol < 0
    tets[neg, 1], tets[neg, 2] = tets[neg, 2].copy(), tets[neg, 1].copy()
    # boundary faces on the top and bottom: faces of the tets lying in a plane
    faces = np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]], tets[:, [1, 2, 3]]])
    fz = pts[faces, 2]
    top = faces[np.all(np.abs(fz) < 1e-12, axis=1)]
    bot = faces[np.all(np.abs(fz + D) < 1e-12, axis=1)]
    ntet = len(tets)
    with open(out, "w") as fp:
        fp.write("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n")
        fp.write('$PhysicalNames\n3\n2 1 "rim"\n2 3 "contact"\n3 4 "tire"\n$EndPhysicalNames\n')
        fp.write("$Entities\n0 0 2 1\n")
        fp.write(f"1 {-L} {-L} {-D} {L} {L} {-D} 1 1 0\n")
        fp.write(f"3 {-L} {-L} 0 {L} {L} 0 1 3 0\n")
        fp.write(f"1 {-L} {-L} {-D} {L} {L} 0 1 4 0\n$EndEntities\n")
        fp.write(f"$Nodes\n1 {len(pts)} 1 {len(pts)}\n3 1 0 {len(pts)}\n")
        fp.write("".join(f"{i + 1}\n" for i in range(len(pts))))
        np.savetxt(fp, pts, fmt="%.12g")
        fp.write("$EndNodes\n")
        ne = ntet + len(top) + len(bot)
        fp.write(f"$Elements\n3 {ne} 1 {ne}\n")
        fp.write(f"3 1 4 {ntet}\n")
        np.savetxt(fp, np.column_stack([np.arange(1, ntet + 1), tets + 1]), fmt="%d")
        fp.write(f"2 1 2 {len(bot)}\n")
        np.savetxt(fp, np.column_stack([np.arange(ntet + 1, ntet + len(bot) + 1), bot + 1]), fmt="%d")
        fp.write(f"2 3 2 {len(top)}\n")
        np.savetxt(fp, np.column_stack([np.arange(ntet + len(bot) + 1, ne + 1), top + 1]), fmt="%d")
        fp.write("$EndElements\n")
    print(f"{out}: {len(pts)} nodes, {ntet} tetrahedra, {len(top)} contact triangles, h {h} m")


if __name__ == "__main__":
    main()
