"""Camera driver adapters: one small interface (:class:`Camera`), adapters for file replay, the
simulated digital-twin camera and real Prophesee / iniVation cameras (imported only when configured)."""
