#!/bin/bash
# Unpacks the lavapipe (Mesa's software Vulkan driver) of Debian's unstable suite, with the LLVM
# and the C library it needs, into DIR without touching the system's packages, and writes
# DIR/run.sh, which runs a program on it: the newest Mesa of BENCHMARKS.md's software-adapter
# rows. Needs apt (Debian or a derivative) and its configured Debian mirror.
#
#   benches/lavapipe_unstable.sh /opt/lavapipe
#   /opt/lavapipe/run.sh target/release/wgsph bench --paths gpu --neighbour-skin 0.1
set -euo pipefail
dir=${1:?usage: $0 DIR}
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
state="$dir/apt"
mkdir -p "$state/lists/partial" "$state/cache/archives/partial" "$state/debs"
# The mirror the system already uses for Debian, with the unstable suite.
uri=$(grep -hs '^URIs:' /etc/apt/sources.list.d/*.sources | awk '{print $2}' | grep -m1 'debian/\?$' || true)
if [ -z "$uri" ]; then
    uri=$(grep -hs '^deb ' /etc/apt/sources.list | awk '{print $2}' | grep -m1 'debian/\?$' || true)
fi
[ -n "$uri" ] || { echo "$0: no Debian mirror in the apt sources" >&2; exit 1; }
echo "deb [signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] $uri sid main" > "$state/sources.list"
apt=(-o Dir::Etc::SourceList="$state/sources.list" -o Dir::Etc::SourceParts=/dev/null
     -o Dir::State::Lists="$state/lists" -o Dir::Cache="$state/cache")
apt-get "${apt[@]}" update -qq
# The driver and everything it depends on, recursively (real packages only).
packages=$(apt-cache "${apt[@]}" depends --recurse --no-recommends --no-suggests --no-conflicts \
    --no-breaks --no-replaces --no-enhances mesa-vulkan-drivers | grep '^[a-z0-9]' | sort -u)
(cd "$state/debs" && apt-get "${apt[@]}" download $packages >/dev/null 2>&1 || \
    for p in $packages; do apt-get "${apt[@]}" download "$p" >/dev/null 2>&1 || true; done)
for deb in "$state/debs"/*.deb; do dpkg-deb -x "$deb" "$dir"; done
lib="$dir/usr/lib/x86_64-linux-gnu"
loader=
for l in "$dir"/usr/lib64/ld-linux-x86-64.so.2 "$dir"/lib64/ld-linux-x86-64.so.2; do
    if [ -z "$loader" ] && [ -e "$l" ]; then loader=$l; fi
done
[ -n "$loader" ] || { echo "$0: the unpacked C library has no dynamic loader" >&2; exit 1; }
sed "s#\"library_path\": *\"[^\"]*\"#\"library_path\": \"$lib/libvulkan_lvp.so\"#" \
    "$dir/usr/share/vulkan/icd.d/lvp_icd.json" > "$dir/lvp.json"
cat > "$dir/run.sh" <<RUN
#!/bin/bash
# Runs a program with the lavapipe unpacked here (and the C library it was built against).
exec env VK_ICD_FILENAMES="$dir/lvp.json" WGPU_BACKEND=vulkan "$loader" --library-path "$lib" "\$@"
RUN
chmod +x "$dir/run.sh"
"$dir/run.sh" /bin/true
echo "$(ls "$state/debs" | grep -m1 '^mesa-vulkan-drivers') unpacked in $dir; run programs with $dir/run.sh"
