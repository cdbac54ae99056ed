#pragma once
// Names the calling thread (at most 15 characters; longer names are cut), so `top -H`, perf
// and debuggers tell the ray threads, the loader and its I/O workers apart.

#include <pthread.h>

#include <string>

namespace raystack {

inline void SetThreadName(const std::string& name) {
  pthread_setname_np(pthread_self(), name.substr(0, 15).c_str());
}

}  // namespace raystack
