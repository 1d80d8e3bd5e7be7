#!/usr/bin/env bash
# One way to open an output (docs/safety.md): every file tetstream writes is opened by
# io/output_file.cpp (OutputClaim/OutputFile for what the user named, create_work_file
# for the files of the job's own directories). This lint fails when any other source
# opens a file for writing by another route: open(2) with O_CREAT or O_TRUNC, fopen
# or Python's open() in a writing mode, std::ofstream/std::fstream, creat, mkstemp,
# numpy's tofile/save to a path.
# Usage: check_outputs.sh SOURCE_ROOT
set -euo pipefail
root=${1:-.}
cd "$root"
# Files allowed to open outputs: the mechanism itself; HDF5's library, which can only
# create a file by name (mesh_export_xdmf.cpp creates it at the partial path the
# OutputClaim holds, and checks afterwards that the path is still the claimed file).
allowed='^(io/output_file\.cpp|io/mesh_export_xdmf\.cpp:.*H5Fcreate)'
pattern='O_CREAT|O_TRUNC|std::ofstream|std::fstream|[^a-z_]creat\(|mkstemp|[^d]fopen\(|\bopen\([^)]*["'"'"'][wax]b?\+?["'"'"']|\.tofile\(|np\.save\(|os\.open\(|H5Fcreate'
found=$(grep -rnE --include='*.cpp' --include='*.hpp' --include='*.ipp' --include='*.h' --include='*.py' \
          "$pattern" core io pipeline tools python 2>/dev/null | grep -vE "$allowed" | grep -vE 'fopen\([^,]*, "rb?"\)' | grep -vE '^[^:]+:[0-9]+:\s*(//|#)' || true)
if [ -n "$found" ]; then
  echo "FAIL: files opened for writing outside io/output_file.cpp (use io::OutputFile, io::OutputClaim or io::create_work_file):" >&2
  echo "$found" >&2
  exit 1
fi
# The lint must see the mechanism itself, or it checks nothing.
grep -q 'O_CREAT | O_EXCL | O_NOFOLLOW' io/output_file.cpp || { echo "FAIL: io/output_file.cpp no longer creates with O_EXCL | O_NOFOLLOW" >&2; exit 1; }
echo "check_outputs: ok"
