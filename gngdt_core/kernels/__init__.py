"""Numba kernels of the growing-gas learners, one module per data structure (as pynndescent).

- `layout`: the estimator's arrays and the constants indexing them, shared by every kernel;
- `graph`: the adjacency (edge slots, edge and node deletion);
- `grid`: the spatial hash grid and the winner searches (squared distances, nearest two);
- `normals`: eq. 16 normals and the eq. 4/9 tests that give an edge its property bits;
- `learning`: the learning loop (Steps 1-9), node insertion and forgetting;
- `segmentation`: kernels over a learned network (fresh normals, nearest-node labelling);
- `regions`: the kernels of `segment_network` (patches, region joins, support planes);
- `view`: kernels over a sensor's view (which nodes it could see, what lies between two nodes).

The estimator (`gngdt.core.gas.model`) owns every array; the kernels only read and write them.
"""
