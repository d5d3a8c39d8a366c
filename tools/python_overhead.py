#!/usr/bin/env python3
"""What a solve costs from Python beyond the same solve in C++ (docs/python.md).

    PYTHONPATH=build/release/python python3 tools/python_overhead.py [--patches 1000] [--repeats 30]

Builds the fine problem of synthetic:c_shaped at about --patches patches (3 variables each),
then alternates blocks of calls: procam.solve() timed in Python (arguments in, the GIL released,
Solution and SolverSummary out) and the C++ Solve timed in C++ (procam._solve_seconds_in_cpp).
Prints the median of each and their difference, the binding's overhead per call.
"""

import argparse
import statistics
import time

import procam


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patches", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--method", default="perceptual")
    args = parser.parse_args()
    room = procam.geometry("synthetic:c_shaped", patches=args.patches)
    problem = procam.make_problem(room)
    options = procam.SolverOptions()
    options.method = args.method
    procam.solve(problem, options)  # warm caches and OpenMP's threads
    from_python, in_cpp = [], []
    for _ in range(args.repeats):
        start = time.perf_counter()
        procam.solve(problem, options)
        from_python.append(time.perf_counter() - start)
        in_cpp.extend(procam._procam._solve_seconds_in_cpp(problem, options, 1))
    python_ms = 1e3 * statistics.median(from_python)
    cpp_ms = 1e3 * statistics.median(in_cpp)
    print(f"{args.method}, {problem.size} patches ({3 * problem.size} variables), {args.repeats} calls each")
    print(f"  from Python: median {python_ms:.3f} ms")
    print(f"  C++ alone:   median {cpp_ms:.3f} ms")
    print(f"  overhead:    {python_ms - cpp_ms:+.3f} ms per call")


if __name__ == "__main__":
    main()
