"""SoRB (Search on the Replay Buffer) as a registered baseline (`algorithm: sorb`)."""
