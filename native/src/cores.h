// meshlab-sharp native library: how many threads a step of the library runs on (internal
// C++ header, shared by the detection sequence and the feature curves).
#ifndef MESHLAB_SHARP_CORES_H
#define MESHLAB_SHARP_CORES_H

#include <algorithm>
#include <thread>

#ifdef __linux__
#include <sched.h>
#endif

namespace sharp {

// One thread per core this process may use (as _kernels._workers).
inline unsigned cores()
{
#ifdef __linux__
	cpu_set_t set;
	if (sched_getaffinity(0, sizeof set, &set) == 0) return unsigned(std::max(1, CPU_COUNT(&set)));
#endif
	return std::max(1u, std::thread::hardware_concurrency());
}

}  // namespace sharp

#endif
