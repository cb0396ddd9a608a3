// A poison header for test_core_links_alone (CMakeLists.txt): this folder comes first on the
// include path of the check, so any header of the solver core that includes nlohmann/json.hpp
// (directly or through another header) stops the compiler here. The core must build with Eigen
// and OpenMP only; JSON belongs to the application, CHOLMOD to the test oracle.
#error "the solver core must not include nlohmann/json.hpp"
