"""PROFIBUS DP: the services (Set_Prm, Chk_Cfg, Slave_Diag, Data_Exchange, Global_Control),
a slave's start-up as a state machine, and the PPOs that carry PKW and PZD words."""

__all__: list[str] = []
