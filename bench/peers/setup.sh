#!/bin/sh
# Install the peer solvers used only by the benchmarks in bench/ (users never need them):
#   CalculiX (ccx, SPOOLES)           Debian package calculix-ccx
#   DOLFINx 0.5 with PETSc and MUMPS  Debian package python3-dolfinx (system python3 only)
#   OpenBLAS                          libopenblas0-pthread: replaces Debian's reference BLAS
#                                     (the default) under MUMPS, as any tuned install would
# Run as root (or through sudo) on Debian/Ubuntu. Prints the installed versions.
set -eu
export DEBIAN_FRONTEND=noninteractive
apt-get update
apt-get install -y --no-install-recommends calculix-ccx python3-dolfinx libopenblas0-pthread time
echo "ccx: $(command -v ccx)"
/usr/bin/python3 -c "import dolfinx, petsc4py; print('dolfinx', dolfinx.__version__, '| petsc4py', petsc4py.__version__)"
