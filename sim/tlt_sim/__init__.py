"""The MuJoCo digital twin of the EDU and the device emulators behind its real driver links."""
