"""The acr design: its plug-in (design) and its report sections."""
