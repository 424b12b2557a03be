# device-debs.sh - sourced by the device scripts: Debian 12's hwloc and
# pkgconf packages in .devwl/debs (scripts/device-ceiling.sh says how to get
# them) unpacked under /tmp/wl-pkgs and put on the paths, for a device
# machine without libhwloc-dev.
P=/tmp/wl-pkgs
for f in .devwl/debs/*.deb; do dpkg -x "$f" "$P"; done
sed -i "s|^prefix=.*|prefix=$P/usr|" "$P"/usr/lib/x86_64-linux-gnu/pkgconfig/hwloc.pc
export PATH=$PATH:$P/usr/bin
command -v pkg-config > /dev/null || ln -sf "$P/usr/bin/pkgconf" "$P/usr/bin/pkg-config"
export PKG_CONFIG_PATH=$P/usr/lib/x86_64-linux-gnu/pkgconfig LD_LIBRARY_PATH=$P/usr/lib/x86_64-linux-gnu
