from fuelhm_bench.cli import console_main

console_main()
