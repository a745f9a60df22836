#!/usr/bin/env bash
# ctest `install_and_examples` (label install): the package as a user gets it. Installs the build
# into a temporary prefix, builds examples/cpp against it with find_package(raytime) and runs it,
# runs the installed binary, and builds the two .deb files with cpack and checks the Depends they
# declare. Usage: check_install.sh BUILD_DIR SOURCE_DIR.
set -euo pipefail
build=$1
source=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
prefix="$tmp/prefix"

cmake --install "$build" --prefix "$prefix" >/dev/null
echo "installed: $(find "$prefix" -type f | wc -l) files, $(du -sh "$prefix" | cut -f1)"
for path in bin/raytime include/raytime/refine/scene.h include/raytime/refine/solve/gnc.h \
  lib/libraytime_refine.a lib/cmake/raytime/raytimeConfig.cmake \
  share/raytime/configs/presets/refine/auto.yaml share/raytime/scripts/plot_campaign.py \
  share/raytime/data/sample/fountain-P11; do
  [[ -e "$prefix/$path" ]] || { echo "missing from the install: $path" >&2; exit 1; }
done
"$prefix/bin/raytime" --version
# The installed demo names the installed sample (packaging/install_demo.cmake).
grep -q "root: $prefix/share/raytime/data/sample/fountain-P11" \
  "$prefix/share/raytime/configs/demo.yaml"
# A preset found by the installed binary without the source tree: RAYTIME_PRESET_DIR unset, the
# lookup's first candidate is share/raytime beside bin/. A bad preset name lists the folder it read.
if "$prefix/bin/raytime" refine --preset no_such_preset --out "$tmp/refine.h5" \
  >"$tmp/preset.log" 2>&1; then
  echo "a missing preset was accepted" >&2
  exit 1
fi
if ! grep -q "$prefix/share/raytime/configs/presets/refine" "$tmp/preset.log"; then
  cat "$tmp/preset.log" >&2
  echo "the installed binary did not read its installed presets" >&2
  exit 1
fi

# The C++ example against the installed package only (CMAKE_PREFIX_PATH), as a user builds it.
cmake -S "$source/examples/cpp" -B "$tmp/example" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build "$tmp/example" >/dev/null
"$tmp/example/refine_synthetic"

# The Python module, where this build has one (python/): its array example on the installed
# package (Debian's python3 and python3-numpy, as the .deb declares).
python_dir="$prefix/lib/python3/dist-packages"
if [[ -d "$python_dir/raytime" && -f "$source/examples/python/refine_arrays.py" ]]; then
  PYTHONPATH="$python_dir" /usr/bin/python3 "$source/examples/python/refine_arrays.py"
fi

# The .deb files and their declared dependencies (cpack -G DEB, as packaging/CMakeLists.txt sets).
if ! command -v dpkg-deb >/dev/null || ! command -v dpkg-shlibdeps >/dev/null; then
  echo "no dpkg-deb / dpkg-shlibdeps here: .deb check skipped"
  exit 0
fi
(cd "$tmp" && cpack --config "$build/CPackConfig.cmake" -B "$tmp/deb" >/dev/null)
for deb in "$tmp"/deb/raytime_*.deb "$tmp"/deb/raytime-dev_*.deb; do
  echo "$(basename "$deb"): $(du -h "$deb" | cut -f1)"
  dpkg-deb -f "$deb" Depends | tee "$tmp/depends"
  case $(basename "$deb") in
    raytime_*)
      expected="libopencv-core406 libhdf5 libtbb12 libyaml-cpp libspdlog libcholmod3"
      # The module's own (python/CMakeLists.txt, RAYTIME_DEBIAN_DEPENDS).
      if [[ -d "$python_dir/raytime" ]]; then expected+=" python3-numpy"; fi
      ;;
    *) expected="raytime libceres-dev libopencv-dev libhdf5-dev libopengv-dev libxxhash-dev" ;;
  esac
  for package in $expected; do
    grep -q "$package" "$tmp/depends" || { echo "$deb does not depend on $package" >&2; exit 1; }
  done
done
# Whole outputs into files: `| grep -q` would close the pipe early, and pipefail fail the test.
dpkg-deb --fsys-tarfile "$tmp"/deb/raytime_*.deb > "$tmp/runtime.tar"
tar -xOf "$tmp/runtime.tar" ./usr/share/raytime/configs/demo.yaml > "$tmp/demo.yaml"
grep -q "root: /usr/share/raytime/data/sample/fountain-P11" "$tmp/demo.yaml" ||
  { echo "the packaged demo.yaml does not name /usr/share/raytime's sample" >&2; exit 1; }
echo "install, example and .deb checks passed"
