# Included after project() by the cross toolchain (aarch64-linux-gnu.cmake): libraries are
# looked for as static archives only, since its programs are linked statically.
set(CMAKE_FIND_LIBRARY_SUFFIXES .a)
