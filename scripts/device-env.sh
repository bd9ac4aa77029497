# Sourced by the scripts that run on the GPU machine (bench-on-device.sh, pile-on-device.sh,
# test-on-device.sh, device-check.sh): the Vulkan loader from the carried .gl/ debs and the
# NVIDIA driver's paths (../shared/device/prelude.sh), so wgpu finds the GPU; and the gzipped
# builds of scripts/build-devbin.sh unpacked.
if compgen -G ".gl/*.deb" > /dev/null; then
  for f in .gl/*.deb; do dpkg -x "$f" / > /dev/null; done
  ldconfig
fi
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
export WGPU_BACKEND=vulkan
for f in .devbin/*.gz .devbin/*/*.gz; do
  [ -e "$f" ] || continue
  gunzip -f "$f" && chmod +x "${f%.gz}"
done
