# CMake toolchain for Debian's arm64 cross compiler (g++-aarch64-linux-gnu), with the target's
# libraries from Debian multiarch (liblz4-dev:arm64 and the like in /usr/lib/aarch64-linux-gnu)
# and its programs run by qemu-aarch64-static, for try-runs, test discovery and ctest alike.
# Used by deploy/check-arm64.sh.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64-static -L /usr/aarch64-linux-gnu)

# Headers and CMake packages from the shared /usr (arch-independent or multiarch), programs
# (pkg-config, cmake helpers) from the host. Libraries are searched in both roots too: the
# target's are found first because CMAKE_LIBRARY_ARCHITECTURE and PKG_CONFIG_LIBDIR point the
# searches at /usr/lib/aarch64-linux-gnu.
set(CMAKE_FIND_ROOT_PATH /usr/aarch64-linux-gnu /usr)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)
set(ENV{PKG_CONFIG_LIBDIR} /usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig)

# Programs linked statically: under Debian 12's qemu-user (7.2) a dynamically linked arm64
# program hangs as it starts its first thread (a std::thread "hello" does), while the same
# program linked statically runs.
set(CMAKE_EXE_LINKER_FLAGS_INIT -static)
# Static archives found first (liblz4.a rather than the .so pkg-config's target would name): set
# after project(), where CMake's platform files would otherwise reset the suffixes.
set(CMAKE_PROJECT_INCLUDE ${CMAKE_CURRENT_LIST_DIR}/static-libraries.cmake)
