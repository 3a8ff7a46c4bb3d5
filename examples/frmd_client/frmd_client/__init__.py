"""The simulator-independent client side of FRMD's policy server, shared by the benchmark packages
in examples/ (MetaWorld, ManiSkill): the protocol codec and client (`protocol`), a mock server
(`mock_server`, `session`), served and in-process policies (`policy_client`), the closed-loop
evaluation loop and report fields (`evaluation`), the metrics of docs/design.md section 6
(`metrics`), resumable benchmark steps (`runner`) and the results tables (`report`)."""
