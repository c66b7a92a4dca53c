"""srlab's brain on outside worlds: Gymnasium environments and simulators srlab did not build."""
