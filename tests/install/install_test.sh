#!/usr/bin/env bash
# The installed package as a user gets it: `cmake --install` into a scratch prefix in the
# build tree; a program built against it with find_package(tetstream) (tests/install/)
# and with pkg-config reads a container with io::TetReader and agrees with `tetstream
# info`; the man page, the completions and the Debian package (cpack -G DEB).
# Usage: bash install_test.sh BUILD_DIR
set -euo pipefail
build=$(realpath "${1:?usage: install_test.sh BUILD_DIR}")
src=$(cd "$(dirname "$0")" && pwd)
scratch="$build/install-test"
rm -rf "$scratch"
mkdir -p "$scratch"
[ -n "${KEEP_SCRATCH:-}" ] || trap 'rm -rf "$scratch"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
prefix="$scratch/prefix"

cmake --build "$build" --target tetstream tetstream_man tetstream_api >/dev/null
cmake --install "$build" --prefix "$prefix" >"$scratch/install.log" || fail "cmake --install: $(tail -5 "$scratch/install.log")"
T="$prefix/bin/tetstream"
[ -x "$T" ] || fail "no binary in $prefix/bin"
for f in lib/libtetstream_io.a lib/libtetstream_core.a lib/libtetstream_pipeline_run.a lib/libtetstream_api.a \
  include/tetstream/tetstream.hpp include/tetstream/io/tet_reader.hpp include/tetstream/core/error.hpp \
  lib/cmake/tetstream/tetstreamConfig.cmake lib/cmake/tetstream/tetstreamConfigVersion.cmake \
  lib/cmake/tetstream/tetstreamTargets.cmake lib/pkgconfig/tetstream.pc share/man/man1/tetstream.1 \
  share/bash-completion/completions/tetstream share/zsh/vendor-completions/_tetstream; do
  [ -f "$prefix/$f" ] || fail "not installed: $f"
done

# A container to read.
cd "$scratch"
"$T" -q gen --n 2000 --seed 3 -o p.f64
"$T" -q run p.f64 -o p.tets --memory 64M
expected=$("$T" -q --json info p.tets | python3 -c 'import json, sys; print(json.load(sys.stdin)["tets"])')
[ "$expected" -gt 0 ] || fail "info: no tets"

# find_package(tetstream), as a user's CMake project.
cmake -S "$src" -B "$scratch/consumer" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Release \
  >"$scratch/consumer.log" 2>&1 || fail "configure with find_package: $(tail -20 "$scratch/consumer.log")"
cmake --build "$scratch/consumer" >>"$scratch/consumer.log" 2>&1 || fail "build: $(tail -20 "$scratch/consumer.log")"
got=$("$scratch/consumer/count_tets" p.tets)
[ "$got" = "$expected" ] || fail "find_package program counts $got tets, info says $expected"
# the public API (docs/cpp.md): run out of core, read the container, triangulate in memory
api=$("$scratch/consumer/api_example" p.f64 api.tets) || fail "api_example: $api"
[ "$api" = "2000 points, $expected tets out of core, $expected in memory, the same" ] || fail "api_example: $api"

# pkg-config, without CMake.
export PKG_CONFIG_PATH="$prefix/lib/pkgconfig"
[ "$(pkg-config --modversion tetstream)" = "$("$T" --version | awk '{print $2}')" ] || fail "pkg-config version"
# shellcheck disable=SC2046
c++ -O1 -o count_pc "$src/count_tets.cpp" $(pkg-config --cflags tetstream) $(pkg-config --libs tetstream) \
  2>"$scratch/pc.log" || fail "build with pkg-config: $(tail -20 "$scratch/pc.log")"
[ "$(./count_pc p.tets)" = "$expected" ] || fail "pkg-config program count"
c++ -O1 -o api_pc "$src/api_example.cpp" $(pkg-config --cflags tetstream) $(pkg-config --libs tetstream) \
  2>"$scratch/pc.log" || fail "build api_example with pkg-config: $(tail -20 "$scratch/pc.log")"
./api_pc p.f64 api2.tets | grep -q ', the same$' || fail "api_example built with pkg-config"

# The man page: roff with every subcommand; the completions complete.
man_page="$prefix/share/man/man1/tetstream.1"
grep -q '^\.TH TETSTREAM 1' "$man_page" || fail "man page header"
for sub in gen run info cat verify field convert clean; do
  grep -q "^\.SS $sub\$" "$man_page" || fail "man page lacks $sub"
done
grep -q '^\.SH EXIT STATUS' "$man_page" || fail "man page: exit status"
# shellcheck disable=SC1091
source "$prefix/share/bash-completion/completions/tetstream"
COMP_WORDS=("$T" con); COMP_CWORD=1; _tetstream
[ "${COMPREPLY[*]}" = convert ] || fail "bash completion of 'con': ${COMPREPLY[*]}"
COMP_WORDS=("$T" convert --bin); COMP_CWORD=2; _tetstream
[ "${COMPREPLY[*]}" = --binary ] || fail "bash completion of 'convert --bin': ${COMPREPLY[*]}"
# values, from the binary's help: --dist of gen, --format of run and of cat
COMP_WORDS=("$T" gen --dist ""); COMP_CWORD=3; _tetstream
for d in uniform clusters grid terrain; do
  [[ " ${COMPREPLY[*]} " == *" $d "* ]] || fail "bash completion of 'gen --dist': ${COMPREPLY[*]}"
done
COMP_WORDS=("$T" gen --dist cl); COMP_CWORD=3; _tetstream
[ "${COMPREPLY[*]}" = clusters ] || fail "bash completion of 'gen --dist cl': ${COMPREPLY[*]}"
COMP_WORDS=("$T" run p.f64 --format ""); COMP_CWORD=4; _tetstream
[ "$(printf '%s\n' "${COMPREPLY[@]}" | sort | tr '\n' ' ')" = "f32 f64 hdf5 las npy ply raw text " ] ||
  fail "bash completion of 'run --format': ${COMPREPLY[*]}"
COMP_WORDS=("$T" cat p.tets --format u); COMP_CWORD=4; _tetstream
[ "$(printf '%s\n' "${COMPREPLY[@]}" | sort | tr '\n' ' ')" = "u32 u64 " ] || fail "bash completion of 'cat --format u': ${COMPREPLY[*]}"
# containers where a container is read: q.tets, not q.f64 (both are here)
mkdir completion && cd completion && touch q.tets q.f64
COMP_WORDS=("$T" cat q); COMP_CWORD=2; _tetstream
[ "${COMPREPLY[*]}" = q.tets ] || fail "bash completion of 'cat q': ${COMPREPLY[*]}"
COMP_WORDS=("$T" -q field --memory 1G q); COMP_CWORD=5; _tetstream
[ "${COMPREPLY[*]}" = q.tets ] || fail "bash completion of 'field --memory 1G q': ${COMPREPLY[*]}"
COMP_WORDS=("$T" convert q.tets q); COMP_CWORD=3; _tetstream
[ "$(printf '%s\n' "${COMPREPLY[@]}" | sort | tr '\n' ' ')" = "q.f64 q.tets " ] || fail "bash completion of 'convert q.tets q': ${COMPREPLY[*]}"
cd "$scratch"

# The Debian package.
(cd "$scratch" && cpack -G DEB -B "$scratch/deb" --config "$build/CPackConfig.cmake" >"$scratch/cpack.log" 2>&1) ||
  fail "cpack -G DEB: $(tail -20 "$scratch/cpack.log")"
deb=$(ls "$scratch"/deb/tetstream_*.deb)
dpkg-deb -c "$deb" >contents.txt
for f in ./usr/bin/tetstream ./usr/lib/libtetstream_io.a ./usr/include/tetstream/io/tet_reader.hpp \
  ./usr/lib/cmake/tetstream/tetstreamConfig.cmake ./usr/share/man/man1/tetstream.1; do
  grep -q " $f\$" contents.txt || fail "the .deb lacks $f"
done
[ "$(dpkg-deb -f "$deb" Package)" = tetstream ] || fail ".deb control"
echo "install test: passed ($expected tets)"
