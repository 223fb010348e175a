#pragma once
// Names the calling thread, so that `top -H`, `perf report --sort comm` and gdb tell vofusion's threads
// apart (the loop closer's CPU per frame is one of issue 33's figures). Linux keeps at most 15
// characters; a longer name is cut there rather than refused.
#include <pthread.h>

#include <string>

namespace vofusion {

inline void nameThisThread(const std::string& name) { pthread_setname_np(pthread_self(), name.substr(0, 15).c_str()); }

}  // namespace vofusion
